#include "sim/ground_truth.h"

// Ground-truth file format (YAML)
// -------------------------------
//
//   ground_truth: {scene: demo_cell, rate_hz: 30, frames: 2}
//   frames:
//     - frame: 0                      # frame index (integer)
//       time_s: 0                     # scene time of the frame, seconds
//       people:                       # every person of the scene, possibly []
//         - name: alice               # person name from the scene file
//           action: walk              # stand | walk | crouch | crawl | reach
//           heading_rad: 1.5707963267948966   # facing, from +x counter-clockwise
//           centre: [x, y, z]         # centre of the bounding box of all parts (m)
//           ellipsoid_half_axes: [a, b, c]    # axis-aligned ellipsoid around centre
//                                             # that contains every part (m)
//           velocity: [vx, vy, vz]    # velocity of the feet position (m/s)
//           parts:                    # all 13 parts, each a capsule: segment a-b
//             head: {a: [x, y, z], b: [x, y, z], radius: r}   # swept by radius (m)
//             torso: {...}
//             pelvis: {...}
//             upper_arm_left: {...}
//             forearm_left: {...}     # elbow to fingertips
//             upper_arm_right: {...}
//             forearm_right: {...}
//             thigh_left: {...}
//             shin_left: {...}
//             thigh_right: {...}
//             shin_right: {...}
//             foot_left: {...}
//             foot_right: {...}
//     - frame: 1
//       ...
//
// World frame: metres, z up. `ground_truth.frames` must equal the length of the
// `frames` list. Numbers are written with 17 significant digits, so reading a
// written file gives back every double bit for bit. Every key is required,
// unknown and duplicate keys are errors, and every number must be finite
// (radii positive, half-axes non-negative). Errors name the file, the line and
// the key path, e.g. "gt.yaml:41: frames[3].people[0].parts.head.radius: not a
// number".

#include <array>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "common/config_error.h"
#include "common/yaml_file.h"

namespace hg::sim {
namespace {

using common::ConfigError;
using Eigen::Vector3d;

/// yaml-cpp marks are 0-based; messages use 1-based lines (0 = unknown, omitted).
int LineOf(const YAML::Node& node) { return common::YamlLine(node); }

/// One YAML map with a fixed set of keys, all required. `where` is the key
/// path of the map in messages ("frames[2].people[0]"), empty at the top.
class MapReader {
 public:
  MapReader(const YAML::Node& node, const std::string& file, std::string where,
            std::initializer_list<const char*> keys)
      : node_(node), file_(file), where_(std::move(where)) {
    if (!node_.IsMap()) {
      throw ConfigError::At(file_, LineOf(node_), Named() + "expected a map");
    }
    std::set<std::string> known;
    for (const char* key : keys) {
      known.insert(key);
    }
    for (const auto& kv : node_) {
      const int line = LineOf(kv.first);
      if (!kv.first.IsScalar()) {
        throw ConfigError::At(file_, line, Named() + "keys must be strings");
      }
      const std::string key = kv.first.Scalar();
      if (known.count(key) == 0) {
        throw ConfigError::At(file_, line, Named() + "unknown key '" + key + "'");
      }
      if (!values_.emplace(key, kv.second).second) {
        throw ConfigError::At(file_, line, Named() + "duplicate key '" + key + "'");
      }
    }
    for (const char* key : keys) {
      if (values_.count(key) == 0) {
        throw ConfigError::At(file_, LineOf(node_), Named() + "missing key '" + key + "'");
      }
    }
  }

  [[nodiscard]] const YAML::Node& operator[](const std::string& key) const {
    return values_.at(key);
  }
  [[nodiscard]] std::string Path(const std::string& key) const {
    return where_.empty() ? key : where_ + "." + key;
  }

 private:
  [[nodiscard]] std::string Named() const { return where_.empty() ? "" : where_ + ": "; }

  const YAML::Node& node_;
  const std::string& file_;
  std::string where_;
  std::map<std::string, YAML::Node> values_;
};

[[noreturn]] void Fail(const std::string& file, const YAML::Node& node, const std::string& path,
                       const std::string& problem) {
  throw ConfigError::At(file, LineOf(node), path + ": " + problem);
}

double ReadNumber(const YAML::Node& node, const std::string& file, const std::string& path) {
  double value = 0.0;
  bool ok = node.IsScalar();
  if (ok) {
    try {
      value = node.as<double>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) {
    Fail(file, node, path, "not a number");
  }
  if (!std::isfinite(value)) {
    Fail(file, node, path, "not finite");
  }
  return value;
}

int ReadInt(const YAML::Node& node, const std::string& file, const std::string& path) {
  int value = 0;
  bool ok = node.IsScalar();
  if (ok) {
    try {
      value = node.as<int>();
    } catch (const YAML::Exception&) {
      ok = false;
    }
  }
  if (!ok) {
    Fail(file, node, path, "not an integer");
  }
  return value;
}

std::string ReadName(const YAML::Node& node, const std::string& file, const std::string& path) {
  if (!node.IsScalar() || node.Scalar().empty()) {
    Fail(file, node, path, "expected a non-empty string");
  }
  return node.Scalar();
}

Vector3d ReadVector(const YAML::Node& node, const std::string& file, const std::string& path) {
  if (!node.IsSequence() || node.size() != 3) {
    Fail(file, node, path, "expected a list of 3 numbers");
  }
  Vector3d v;
  for (int i = 0; i < 3; ++i) {
    v[i] = ReadNumber(node[i], file, path + "[" + std::to_string(i) + "]");
  }
  return v;
}

BodyCapsule ReadCapsule(BodyPart part, const YAML::Node& node, const std::string& file,
                        const std::string& where) {
  const MapReader map(node, file, where, {"a", "b", "radius"});
  BodyCapsule capsule;
  capsule.part = part;
  capsule.a_W = ReadVector(map["a"], file, map.Path("a"));
  capsule.b_W = ReadVector(map["b"], file, map.Path("b"));
  capsule.radius_m = ReadNumber(map["radius"], file, map.Path("radius"));
  if (!(capsule.radius_m > 0.0)) {
    Fail(file, map["radius"], map.Path("radius"), "must be positive");
  }
  return capsule;
}

PersonTruth ReadPerson(const YAML::Node& node, const std::string& file, const std::string& where) {
  const MapReader map(
      node, file, where,
      {"name", "action", "heading_rad", "centre", "ellipsoid_half_axes", "velocity", "parts"});
  PersonTruth person;
  person.name = ReadName(map["name"], file, map.Path("name"));

  const YAML::Node& action = map["action"];
  bool known_action = false;
  if (action.IsScalar()) {
    for (ActionKind kind : {ActionKind::kStand, ActionKind::kWalk, ActionKind::kCrouch,
                            ActionKind::kCrawl, ActionKind::kReach}) {
      if (action.Scalar() == ActionName(kind)) {
        person.state.action = kind;
        known_action = true;
      }
    }
  }
  if (!known_action) {
    Fail(file, action, map.Path("action"), "expected one of stand, walk, crouch, crawl, reach");
  }
  person.state.heading_rad = ReadNumber(map["heading_rad"], file, map.Path("heading_rad"));
  person.state.centre_W = ReadVector(map["centre"], file, map.Path("centre"));
  person.state.ellipsoid_half_axes_m =
      ReadVector(map["ellipsoid_half_axes"], file, map.Path("ellipsoid_half_axes"));
  if ((person.state.ellipsoid_half_axes_m.array() < 0.0).any()) {
    Fail(file, map["ellipsoid_half_axes"], map.Path("ellipsoid_half_axes"),
         "half-axes must not be negative");
  }
  person.state.velocity_W = ReadVector(map["velocity"], file, map.Path("velocity"));

  const YAML::Node& parts = map["parts"];
  const std::string parts_path = map.Path("parts");
  if (!parts.IsMap()) {
    Fail(file, parts, parts_path, "expected a map from part name to capsule");
  }
  std::array<bool, kNumBodyParts> seen{};
  for (const auto& kv : parts) {
    const std::string name = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
    BodyPart part = BodyPart::kHead;
    if (!BodyPartFromName(name, &part)) {
      Fail(file, kv.first, parts_path, "unknown body part '" + name + "'");
    }
    const int index = static_cast<int>(part);
    if (seen[index]) {
      Fail(file, kv.first, parts_path, "duplicate body part '" + name + "'");
    }
    seen[index] = true;
    person.state.parts[index] = ReadCapsule(part, kv.second, file, parts_path + "." + name);
  }
  for (int k = 0; k < kNumBodyParts; ++k) {
    if (!seen[k]) {
      Fail(file, parts, parts_path,
           std::string("missing body part '") + BodyPartName(static_cast<BodyPart>(k)) + "'");
    }
  }
  return person;
}

FrameTruth ReadFrame(const YAML::Node& node, const std::string& file, const std::string& where) {
  const MapReader map(node, file, where, {"frame", "time_s", "people"});
  FrameTruth frame;
  frame.frame = ReadInt(map["frame"], file, map.Path("frame"));
  frame.time_s = ReadNumber(map["time_s"], file, map.Path("time_s"));
  const YAML::Node& people = map["people"];
  const std::string people_path = map.Path("people");
  if (!people.IsSequence()) {
    Fail(file, people, people_path, "expected a list of people");
  }
  std::map<std::string, int> first_line;
  for (std::size_t i = 0; i < people.size(); ++i) {
    const std::string at = people_path + "[" + std::to_string(i) + "]";
    PersonTruth person = ReadPerson(people[i], file, at);
    const int line = LineOf(people[i]);
    const auto [it, inserted] = first_line.emplace(person.name, line);
    if (!inserted) {
      Fail(file, people[i], at + ".name",
           "duplicate person '" + person.name + "' (first at line " + std::to_string(it->second) +
               ")");
    }
    frame.people.push_back(std::move(person));
  }
  return frame;
}

/// Throws when a number that is about to be written would not read back.
void CheckFinite(double value, const std::string& path, const std::string& where) {
  if (!std::isfinite(value)) {
    throw ConfigError::At(path, 0, "cannot write: " + where + ": not finite");
  }
}

void CheckWritable(const std::string& path, const FrameTruth& frame, std::size_t f) {
  const std::string fw = "frames[" + std::to_string(f) + "]";
  CheckFinite(frame.time_s, path, fw + ".time_s");
  for (std::size_t p = 0; p < frame.people.size(); ++p) {
    const BodyState& s = frame.people[p].state;
    const std::string pw = fw + ".people[" + std::to_string(p) + "]";
    CheckFinite(s.heading_rad, path, pw + ".heading_rad");
    for (int i = 0; i < 3; ++i) {
      CheckFinite(s.centre_W[i], path, pw + ".centre");
      CheckFinite(s.ellipsoid_half_axes_m[i], path, pw + ".ellipsoid_half_axes");
      CheckFinite(s.velocity_W[i], path, pw + ".velocity");
    }
    for (const BodyCapsule& c : s.parts) {
      const std::string cw = pw + ".parts." + BodyPartName(c.part);
      CheckFinite(c.radius_m, path, cw + ".radius");
      for (int i = 0; i < 3; ++i) {
        CheckFinite(c.a_W[i], path, cw + ".a");
        CheckFinite(c.b_W[i], path, cw + ".b");
      }
    }
  }
}

YAML::Emitter& operator<<(YAML::Emitter& out, const Vector3d& v) {
  out << YAML::Flow << YAML::BeginSeq << v.x() << v.y() << v.z() << YAML::EndSeq;
  return out;
}

/// One frame as an item of the `frames` list (a block sequence of one).
void EmitFrame(YAML::Emitter& out, const FrameTruth& frame) {
  out << YAML::BeginSeq << YAML::BeginMap;
  out << YAML::Key << "frame" << YAML::Value << frame.frame;
  out << YAML::Key << "time_s" << YAML::Value << frame.time_s;
  out << YAML::Key << "people" << YAML::Value << YAML::BeginSeq;
  for (const PersonTruth& person : frame.people) {
    const BodyState& s = person.state;
    out << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << person.name;
    out << YAML::Key << "action" << YAML::Value << ActionName(s.action);
    out << YAML::Key << "heading_rad" << YAML::Value << s.heading_rad;
    out << YAML::Key << "centre" << YAML::Value << s.centre_W;
    out << YAML::Key << "ellipsoid_half_axes" << YAML::Value << s.ellipsoid_half_axes_m;
    out << YAML::Key << "velocity" << YAML::Value << s.velocity_W;
    out << YAML::Key << "parts" << YAML::Value << YAML::BeginMap;
    for (int k = 0; k < kNumBodyParts; ++k) {
      const BodyCapsule& c = s.parts[k];
      out << YAML::Key << BodyPartName(static_cast<BodyPart>(k)) << YAML::Value;
      out << YAML::Flow << YAML::BeginMap;
      out << YAML::Key << "a" << YAML::Value << c.a_W;
      out << YAML::Key << "b" << YAML::Value << c.b_W;
      out << YAML::Key << "radius" << YAML::Value << c.radius_m;
      out << YAML::EndMap;
    }
    out << YAML::EndMap;
    out << YAML::EndMap;
  }
  out << YAML::EndSeq;
  out << YAML::EndMap << YAML::EndSeq;
}

}  // namespace

void WriteGroundTruth(const std::string& path, const GroundTruth& truth) {
  GroundTruthWriter writer(path, truth.scene, truth.rate_hz, truth.frames.size());
  for (const FrameTruth& frame : truth.frames) writer.Add(frame);
  writer.Finish();
}

GroundTruthWriter::GroundTruthWriter(const std::string& path, const std::string& scene,
                                     double rate_hz, std::size_t frames)
    : path_(path), frames_(frames) {
  CheckFinite(rate_hz, path, "ground_truth.rate_hz");
  YAML::Emitter head;
  head.SetDoublePrecision(std::numeric_limits<double>::max_digits10);
  head << YAML::BeginMap;
  head << YAML::Key << "ground_truth" << YAML::Value << YAML::Flow << YAML::BeginMap;
  head << YAML::Key << "scene" << YAML::Value << scene;
  head << YAML::Key << "rate_hz" << YAML::Value << rate_hz;
  head << YAML::Key << "frames" << YAML::Value << frames;
  head << YAML::EndMap << YAML::EndMap;
  if (!head.good()) throw ConfigError::At(path, 0, "cannot write: " + head.GetLastError());
  file_.open(path, std::ios::out | std::ios::trunc);
  // The list's items follow at the key's own indentation (valid YAML).
  file_ << head.c_str() << "\nframes:" << (frames == 0 ? " []\n" : "\n");
  if (!file_) throw ConfigError::At(path, 0, "cannot write");
}

void GroundTruthWriter::Add(const FrameTruth& frame) {
  if (added_ >= frames_) {
    throw ConfigError::At(path_, 0,
                          "cannot write: more than the " + std::to_string(frames_) + " frames");
  }
  CheckWritable(path_, frame, added_);
  YAML::Emitter out;
  // 17 significant digits make every double read back bit for bit.
  out.SetDoublePrecision(std::numeric_limits<double>::max_digits10);
  EmitFrame(out, frame);
  if (!out.good()) throw ConfigError::At(path_, 0, "cannot write: " + out.GetLastError());
  file_ << out.c_str() << '\n';
  if (!file_) throw ConfigError::At(path_, 0, "cannot write");
  ++added_;
}

void GroundTruthWriter::Finish() {
  if (added_ != frames_) {
    throw ConfigError::At(
        path_, 0,
        "cannot write: " + std::to_string(added_) + " of " + std::to_string(frames_) + " frames");
  }
  file_.close();
  if (!file_) throw ConfigError::At(path_, 0, "cannot write");
}

GroundTruth ReadGroundTruth(const std::string& path) {
  const YAML::Node root = common::LoadYamlFile(path);
  if (!root.IsMap()) {
    throw ConfigError::At(path, root.IsDefined() ? LineOf(root) : 0,
                          "expected a map with the keys 'ground_truth' and 'frames'");
  }
  const MapReader top(root, path, "", {"ground_truth", "frames"});
  const MapReader header(top["ground_truth"], path, "ground_truth", {"scene", "rate_hz", "frames"});

  GroundTruth truth;
  const YAML::Node& scene = header["scene"];
  if (!scene.IsScalar()) {
    Fail(path, scene, header.Path("scene"), "expected a string");
  }
  truth.scene = scene.Scalar();
  truth.rate_hz = ReadNumber(header["rate_hz"], path, header.Path("rate_hz"));
  if (!(truth.rate_hz > 0.0)) {
    Fail(path, header["rate_hz"], header.Path("rate_hz"), "must be positive");
  }
  const int count = ReadInt(header["frames"], path, header.Path("frames"));
  if (count < 0) {
    Fail(path, header["frames"], header.Path("frames"), "must not be negative");
  }

  const YAML::Node& frames = top["frames"];
  if (!frames.IsSequence()) {
    Fail(path, frames, "frames", "expected a list of frames");
  }
  if (frames.size() != static_cast<std::size_t>(count)) {
    Fail(path, frames, "frames",
         "holds " + std::to_string(frames.size()) + " frames, but ground_truth.frames says " +
             std::to_string(count));
  }
  truth.frames.reserve(frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    truth.frames.push_back(ReadFrame(frames[i], path, "frames[" + std::to_string(i) + "]"));
  }
  return truth;
}

}  // namespace hg::sim
