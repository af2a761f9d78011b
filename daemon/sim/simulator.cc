#include "sim/simulator.h"

#include <utility>

namespace hg::sim {

Simulator::Simulator(Scene scene, int num_threads)
    : scene_(std::move(scene)), pool_(num_threads < 1 ? 1 : num_threads) {
  mask_renderers_.reserve(scene_.cameras.size());
  for (const SceneCamera& camera : scene_.cameras) {
    mask_renderers_.emplace_back(camera.model, scene_.obstacles, scene_.foreground_objects,
                                 scene_.mask_occlusion);
  }
  per_camera_people_.resize(scene_.cameras.size());
  for (auto& people : per_camera_people_) {
    people.resize(scene_.people.size());
  }
}

Simulator::~Simulator() = default;

std::vector<BodyState> Simulator::PeopleAt(double t_s) const {
  std::vector<BodyState> people;
  people.reserve(scene_.people.size());
  for (const Person& person : scene_.people) {
    people.push_back(EvaluatePerson(person, t_s));
  }
  return people;
}

FrameTruth Simulator::Truth(int frame, double t_s) const {
  FrameTruth truth;
  truth.frame = frame;
  truth.time_s = t_s;
  for (const Person& person : scene_.people) {
    truth.people.push_back({person.name, EvaluatePerson(person, t_s)});
  }
  return truth;
}

void Simulator::RenderMasks(double t_s, std::vector<common::ImageU8>* masks) {
  masks->resize(scene_.cameras.size());
  auto task = [&](int camera, int /*worker*/) {
    std::vector<BodyState>& people = per_camera_people_[camera];
    const double t_camera = t_s + scene_.cameras[camera].time_offset_s;
    for (std::size_t p = 0; p < people.size(); ++p) {
      people[p] = EvaluatePerson(scene_.people[p], t_camera);
    }
    mask_renderers_[camera].Render(people, &(*masks)[camera]);
  };
  pool_.Run(num_cameras(), task);
}

void Simulator::RenderColour(double t_s, std::uint64_t frame,
                             std::vector<common::ImageRgb8>* frames) {
  if (colour_renderers_.empty()) {
    colour_renderers_.resize(scene_.cameras.size());
    auto build = [&](int camera, int /*worker*/) {
      colour_renderers_[camera] = std::make_unique<ColourRenderer>(scene_, camera);
    };
    pool_.Run(num_cameras(), build);
  }
  frames->resize(scene_.cameras.size());
  auto task = [&](int camera, int /*worker*/) {
    std::vector<BodyState>& people = per_camera_people_[camera];
    const double t_camera = t_s + scene_.cameras[camera].time_offset_s;
    for (std::size_t p = 0; p < people.size(); ++p) {
      people[p] = EvaluatePerson(scene_.people[p], t_camera);
    }
    colour_renderers_[camera]->Render(people, t_camera, frame, &(*frames)[camera]);
  };
  pool_.Run(num_cameras(), task);
}

}  // namespace hg::sim
