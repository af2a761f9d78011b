// `hullguard synth`: render a scene to files — masks, colour frames, cameras,
// obstacle meshes and per-frame ground truth (format: docs/synth.md).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <variant>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "common/cli_checks.h"
#include "common/config_error.h"
#include "common/yaml_file.h"
#include "geometry/camera_yaml.h"
#include "hullguard/commands.h"
#include "silhouette/mask_io.h"
#include "sim/ground_truth.h"
#include "sim/simulator.h"

namespace hg::tools {
namespace {

namespace fs = std::filesystem;

struct SynthFlags {
  std::string scene;
  int frames = 30;
  double start_s = 0.0;
  std::string out;
  bool colour = false;
  bool masks = false;
  int threads = 2;
};

std::string FrameName(int frame) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d.png", frame);
  return buf;
}

void WriteManifest(const fs::path& path, const sim::Scene& scene, const SynthFlags& f, bool masks,
                   bool colour) {
  YAML::Emitter out;
  out.SetDoublePrecision(std::numeric_limits<double>::max_digits10);
  out << YAML::BeginMap << YAML::Key << "synth" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "format" << YAML::Value << 1;
  out << YAML::Key << "scene" << YAML::Value << scene.name;
  out << YAML::Key << "rate_hz" << YAML::Value << scene.rate_hz;
  out << YAML::Key << "start_s" << YAML::Value << f.start_s;
  out << YAML::Key << "frames" << YAML::Value << f.frames;
  out << YAML::Key << "masks" << YAML::Value << masks;
  out << YAML::Key << "colour" << YAML::Value << colour;
  out << YAML::EndMap;
  out << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (const sim::SceneCamera& c : scene.cameras) {
    out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << c.model.name;
    out << YAML::Key << "time_offset_s" << YAML::Value << c.time_offset_s << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  common::WriteYamlFile(path.string(), out);
}

/// A file to copy from `from` to `to` (relative to the output folder).
struct FileCopy {
  fs::path from;
  fs::path to;
};

/// The scene file as scene.yaml, and every mesh file it names by a relative
/// path at that path beside it, so that OUT/scene.yaml loads as the scene did.
/// Absolute mesh paths stay as they are.
/// @throws common::ConfigError for a relative mesh path that leaves the scene's folder.
std::vector<FileCopy> SceneFiles(const sim::Scene& scene, const std::string& scene_file) {
  std::vector<FileCopy> files = {{scene_file, "scene.yaml"}};
  for (const auto* solids : {&scene.obstacles, &scene.foreground_objects}) {
    for (const sim::Solid& solid : *solids) {
      const auto* mesh = std::get_if<sim::MeshSolid>(&solid.geometry);
      if (mesh == nullptr || fs::path(mesh->file).is_absolute()) continue;
      const fs::path to = fs::path(mesh->file).lexically_normal();
      if (to.empty() || *to.begin() == "..") {
        throw common::ConfigError(scene_file + ": mesh file '" + mesh->file +
                                  "' lies outside the scene's folder, so synth cannot copy it "
                                  "beside scene.yaml (use a path inside it or an absolute one)");
      }
      // The names synth writes itself: a copy there would be overwritten
      // (obstacles.obj) or removed with the frames.
      const std::string first = to.begin()->string();
      if (to == "obstacles.obj" || to == "cameras.yaml" || to == "manifest.yaml" ||
          to == "scene.yaml" || to == "ground_truth.yaml" || first == "masks" ||
          first == "colour") {
        throw common::ConfigError(scene_file + ": mesh file '" + mesh->file +
                                  "' has a name synth writes its own output under; rename it "
                                  "(or give an absolute path)");
      }
      files.push_back({mesh->loaded_from, to});
    }
  }
  return files;
}

/// Makes `out` ready for a synth output: a new or empty folder as it is; an
/// earlier synth output (manifest.yaml with a `synth` map) loses its frames
/// and ground truth, so that no stale frame outlives a shorter run.
/// @throws common::ConfigError for any other non-empty folder.
void PrepareOutput(const fs::path& out) {
  std::error_code ec;
  if (!fs::exists(out, ec)) return;
  if (!fs::is_directory(out, ec)) throw common::ConfigError(out.string() + ": not a folder");
  if (fs::is_empty(out, ec)) return;
  bool synth_output = false;
  try {
    const YAML::Node manifest = common::LoadYamlFile((out / "manifest.yaml").string());
    synth_output = manifest.IsMap() && manifest["synth"] && manifest["synth"].IsMap();
  } catch (const common::ConfigError&) {
    synth_output = false;  // No manifest, or not YAML: not ours to clear.
  }
  if (!synth_output) {
    throw common::ConfigError(out.string() +
                              ": folder is not empty and holds no synth output (manifest.yaml); "
                              "choose a new or empty folder");
  }
  for (const char* stale : {"masks", "colour", "ground_truth.yaml"}) {
    fs::remove_all(out / stale, ec);
    if (ec) throw common::ConfigError((out / stale).string() + ": cannot remove: " + ec.message());
  }
}

int RunSynth(const SynthFlags& f) {
  const auto t_begin = std::chrono::steady_clock::now();
  const bool masks = f.masks || !f.colour;  // Masks unless only colour was asked for.
  sim::Scene scene = sim::LoadScene(f.scene);
  const std::vector<FileCopy> scene_files = SceneFiles(scene, f.scene);
  const fs::path out(f.out);
  PrepareOutput(out);
  std::error_code ec;
  for (const sim::SceneCamera& c : scene.cameras) {
    if (masks) fs::create_directories(out / "masks" / c.model.name, ec);
    if (!ec && f.colour) fs::create_directories(out / "colour" / c.model.name, ec);
    if (ec) throw common::ConfigError(f.out + ": cannot create directories: " + ec.message());
  }
  for (const FileCopy& file : scene_files) {
    const fs::path to = out / file.to;
    fs::create_directories(to.parent_path(), ec);
    // Synthesising from an earlier output's own scene.yaml: the files are in place.
    const bool in_place = !ec && fs::exists(to, ec) && fs::equivalent(file.from, to, ec);
    if (!ec && !in_place) fs::copy_file(file.from, to, fs::copy_options::overwrite_existing, ec);
    if (ec) throw common::ConfigError(to.string() + ": " + ec.message());
  }
  geometry::WriteCamerasFile((out / "cameras.yaml").string(), scene.CameraModels());
  geometry::TriangleMesh obstacles;
  for (const geometry::TriangleMesh& m : scene.ObstacleMeshes()) obstacles.Append(m);
  geometry::WriteObj((out / "obstacles.obj").string(), obstacles);
  WriteManifest(out / "manifest.yaml", scene, f, masks, f.colour);

  sim::Simulator simulator(std::move(scene), f.threads);
  const sim::Scene& s = simulator.scene();
  // Frame by frame: a long run holds no ground truth in memory.
  sim::GroundTruthWriter truth((out / "ground_truth.yaml").string(), s.name, s.rate_hz,
                               static_cast<std::size_t>(f.frames));
  std::vector<common::ImageU8> mask_images;
  std::vector<common::ImageRgb8> colour_images;
  double render_ms = 0.0;
  for (int frame = 0; frame < f.frames; ++frame) {
    const double t = f.start_s + frame / s.rate_hz;
    const auto t0 = std::chrono::steady_clock::now();
    if (masks) simulator.RenderMasks(t, &mask_images);
    if (f.colour) simulator.RenderColour(t, static_cast<std::uint64_t>(frame), &colour_images);
    render_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    for (int c = 0; c < simulator.num_cameras(); ++c) {
      const std::string& name = s.cameras[c].model.name;
      if (masks) {
        silhouette::WriteGreyImage((out / "masks" / name / FrameName(frame)).string(),
                                   mask_images[c]);
      }
      if (f.colour) {
        silhouette::WriteRgbImage((out / "colour" / name / FrameName(frame)).string(),
                                  colour_images[c]);
      }
    }
    truth.Add(simulator.Truth(frame, t));
  }
  truth.Finish();
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_begin).count();
  std::printf(
      "hullguard synth: %s, %d cameras, %d frames (%.2f s of scene time) -> %s\n"
      "  wrote%s%s cameras.yaml, obstacles.obj, ground_truth.yaml, manifest.yaml\n"
      "  rendering %.1f ms per frame set, %.1f s in all\n",
      s.name.c_str(), simulator.num_cameras(), f.frames, f.frames / s.rate_hz, f.out.c_str(),
      masks ? " masks," : "", f.colour ? " colour," : "", render_ms / f.frames, total_s);
  return kExitOk;
}

}  // namespace

void RegisterSynth(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<SynthFlags>();
  CLI::App* cmd = app.add_subcommand(
      "synth", "Render a scene: masks, colour frames, cameras, obstacles, ground truth");
  cmd->add_option("--scene", flags->scene, "Scene YAML (docs/scenes.md)")->required();
  cmd->add_option("--frames", flags->frames, "Number of frames")->check(hg::cli::Range(1, 1000000));
  cmd->add_option("--start", flags->start_s, "Scene time of the first frame (s)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--out", flags->out,
                  "Output folder: new, empty or an earlier synth output (docs/synth.md)")
      ->required();
  cmd->add_flag("--colour", flags->colour, "Write colour frames");
  cmd->add_flag("--masks", flags->masks,
                "Write ground-truth masks (the default unless only --colour is given)");
  cmd->add_option("--threads", flags->threads, "Rendering threads")->check(hg::cli::Range(1, 64));
  cmd->callback([flags, exit_code] { *exit_code = RunSynth(*flags); });
}

}  // namespace hg::tools
