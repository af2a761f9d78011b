#include "sim/scene.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>
#include <Eigen/Geometry>

#include "common/config_error.h"
#include "common/input_file.h"
#include "common/limits.h"
#include "common/yaml_file.h"
#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"

namespace hg::sim {
namespace {

using common::ConfigError;

constexpr double kPi = 3.14159265358979323846;

double Radians(double degrees) { return degrees * kPi / 180.0; }

/// Angles in a scene file (degrees): a thousand turns either way at most.
constexpr double kMaxDegrees = 360000.0;
/// Times in a scene file (s): a script lasts at most about 115 days; beyond,
/// its sums lose the frame period and its loops run for ever.
constexpr double kMaxSceneSeconds = 1e7;

/// yaml-cpp marks are 0-based; messages use 1-based lines (0 = unknown, omitted).
int LineOf(const YAML::Node& node) { return common::YamlLine(node); }

std::string Join(const std::vector<std::string>& words) {
  std::string out;
  for (const std::string& w : words) {
    out += (out.empty() ? "" : ", ") + w;
  }
  return out;
}

std::string FormatNumber(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

class MapValue;

/// One value of the scene file together with where it sits: the key path used
/// in messages ("people[1].script[2].walk.speed") and the line reported for a
/// problem with it (the key's line for a map entry, the element's own line for
/// a list element). Every accessor checks type and range and throws
/// "file:line: path: problem". Single-thread; cheap to copy.
class Value {
 public:
  Value(YAML::Node node, std::string path, int line, const std::string* file)
      : node_(std::move(node)), path_(std::move(path)), line_(line), file_(file) {}

  [[nodiscard]] const YAML::Node& node() const { return node_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] int line() const { return line_; }
  [[nodiscard]] const std::string& file() const { return *file_; }

  [[noreturn]] void Fail(const std::string& problem) const {
    throw ConfigError::At(*file_, line_, path_.empty() ? problem : path_ + ": " + problem);
  }

  /// A finite number.
  [[nodiscard]] double Number() const {
    double value = 0.0;
    bool ok = node_.IsScalar();
    if (ok) {
      try {
        value = node_.as<double>();
      } catch (const YAML::Exception&) {
        ok = false;
      }
    }
    if (!ok) Fail("expected a number");
    if (!std::isfinite(value)) Fail("not finite");
    return value;
  }

  [[nodiscard]] double Positive() const {
    const double value = Number();
    if (!(value > 0.0)) Fail("must be > 0");
    return value;
  }

  /// A size or a scale: > 0 and, as coordinates, at most 1e6 (m).
  [[nodiscard]] double Size() const {
    const double value = Positive();
    if (!(value <= common::kMaxCoordinateM)) Fail("must be at most 1e6");
    return value;
  }

  [[nodiscard]] double NonNegative() const {
    const double value = Number();
    if (!(value >= 0.0)) Fail("must be >= 0");
    return value;
  }

  /// An angle in degrees (a thousand turns either way at most), in radians.
  [[nodiscard]] double Degrees() const { return Radians(InRange(-kMaxDegrees, kMaxDegrees)); }

  /// A number in [lo, hi].
  [[nodiscard]] double InRange(double lo, double hi) const {
    const double value = Number();
    if (!(value >= lo && value <= hi)) {
      Fail("must be in [" + FormatNumber(lo) + ", " + FormatNumber(hi) + "]");
    }
    return value;
  }

  [[nodiscard]] bool Bool() const {
    bool value = false;
    bool ok = node_.IsScalar();
    if (ok) {
      try {
        value = node_.as<bool>();
      } catch (const YAML::Exception&) {
        ok = false;
      }
    }
    if (!ok) Fail("expected true or false");
    return value;
  }

  [[nodiscard]] std::uint64_t Unsigned() const {
    std::uint64_t value = 0;
    bool ok = node_.IsScalar();
    if (ok) {
      const std::string& text = node_.Scalar();
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
      ok = ec == std::errc() && end == text.data() + text.size() && !text.empty();
    }
    if (!ok) Fail("expected a non-negative integer");
    return value;
  }

  /// A non-empty string.
  [[nodiscard]] std::string String() const {
    if (!node_.IsScalar() || node_.Scalar().empty()) Fail("expected a non-empty string");
    return node_.Scalar();
  }

  /// The elements of a list, each with its own path and line.
  [[nodiscard]] std::vector<Value> List() const {
    if (!node_.IsSequence()) Fail("expected a list");
    std::vector<Value> out;
    out.reserve(node_.size());
    for (std::size_t i = 0; i < node_.size(); ++i) {
      const YAML::Node element = node_[i];
      const int line = LineOf(element);
      out.emplace_back(element, path_ + "[" + std::to_string(i) + "]", line >= 1 ? line : line_,
                       file_);
    }
    return out;
  }

  /// A list of `min_count` to `max_count` finite numbers.
  [[nodiscard]] std::vector<double> Numbers(std::size_t min_count, std::size_t max_count) const {
    const std::string expected =
        min_count == max_count ? std::to_string(min_count)
                               : std::to_string(min_count) + " or " + std::to_string(max_count);
    if (!node_.IsSequence()) Fail("expected a list of " + expected + " numbers");
    if (node_.size() < min_count || node_.size() > max_count) {
      Fail("expected " + expected + " numbers, got " + std::to_string(node_.size()));
    }
    std::vector<double> out;
    for (const Value& element : List()) {
      // Coordinates and sizes: beyond the cell's largest coordinate they mean
      // nothing, and their squares and sums overflow.
      out.push_back(element.InRange(-common::kMaxCoordinateM, common::kMaxCoordinateM));
    }
    return out;
  }

  [[nodiscard]] Eigen::Vector3d Vector3() const {
    const std::vector<double> v = Numbers(3, 3);
    return {v[0], v[1], v[2]};
  }

  /// [x, y] or [x, y, z]; z defaults to `default_z`.
  [[nodiscard]] Eigen::Vector3d Point(double default_z) const {
    const std::vector<double> v = Numbers(2, 3);
    return {v[0], v[1], v.size() == 3 ? v[2] : default_z};
  }

  /// Three positive numbers (a size).
  [[nodiscard]] Eigen::Vector3d PositiveVector3() const {
    const Eigen::Vector3d v = Vector3();
    const std::vector<Value> elements = List();
    for (int i = 0; i < 3; ++i) {
      (void)elements[i].Positive();
    }
    return v;
  }

  /// [r, g, b], each in [0, 1].
  [[nodiscard]] Rgb Colour() const {
    const Eigen::Vector3d v = Vector3();
    const std::vector<Value> elements = List();
    for (int i = 0; i < 3; ++i) {
      (void)elements[i].InRange(0.0, 1.0);
    }
    return v.cast<float>();
  }

  /// A map whose keys must all be in `known`.
  [[nodiscard]] MapValue Map(std::vector<std::string> known) const;

  /// Every (key, value) of a map with free-form keys (unique, strings).
  [[nodiscard]] std::vector<std::pair<std::string, Value>> Entries() const;

 private:
  YAML::Node node_;
  std::string path_;
  int line_ = 0;
  const std::string* file_;
};

/// A map of the scene file with its keys checked against the known ones.
class MapValue {
 public:
  MapValue(const Value& self, std::vector<std::string> known) : self_(self) {
    if (!self.node().IsMap()) {
      self.Fail("expected a map (keys: " + Join(known) + ")");
    }
    for (const auto& kv : self.node()) {
      const int line = LineOf(kv.first);
      const std::string where = self.path().empty() ? "" : self.path() + ": ";
      if (!kv.first.IsScalar()) {
        throw ConfigError::At(self.file(), line, where + "keys must be strings");
      }
      const std::string key = kv.first.Scalar();
      if (key == "<<") throw ConfigError::At(self.file(), line, where + common::kMergeKeyText);
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        throw ConfigError::At(self.file(), line,
                              where + "unknown key '" + key + "' (known: " + Join(known) + ")");
      }
      const std::string path = self.path().empty() ? key : self.path() + "." + key;
      if (!entries_.emplace(key, Value(kv.second, path, line, &self.file())).second) {
        throw ConfigError::At(self.file(), line, where + "duplicate key '" + key + "'");
      }
    }
  }

  [[nodiscard]] const Value& self() const { return self_; }
  [[nodiscard]] bool Has(const std::string& key) const { return entries_.count(key) != 0; }

  /// A required key.
  [[nodiscard]] const Value& Get(const std::string& key) const {
    const auto it = entries_.find(key);
    if (it == entries_.end()) self_.Fail("missing key '" + key + "'");
    return it->second;
  }

  /// An optional key.
  [[nodiscard]] std::optional<Value> Find(const std::string& key) const {
    const auto it = entries_.find(key);
    if (it == entries_.end()) return std::nullopt;
    return it->second;
  }

  /// The one key of `alternatives` that is present; an error when none or
  /// several are.
  [[nodiscard]] std::string OneOf(const std::vector<std::string>& alternatives) const {
    std::vector<std::string> found;
    int last_line = 0;  // Reported at the later of the clashing keys.
    for (const std::string& key : alternatives) {
      if (!Has(key)) continue;
      found.push_back(key);
      last_line = std::max(last_line, Get(key).line());
    }
    if (found.empty()) self_.Fail("needs one of " + Join(alternatives));
    if (found.size() > 1) {
      throw ConfigError::At(
          self_.file(), last_line,
          Prefix() + "give only one of " + Join(alternatives) + " (found " + Join(found) + ")");
    }
    return found.front();
  }

  /// An error when any key of `a` and any key of `b` are both present.
  void Exclusive(const std::vector<std::string>& a, const std::vector<std::string>& b,
                 const std::string& problem) const {
    for (const std::string& key_b : b) {
      if (!Has(key_b)) continue;
      for (const std::string& key_a : a) {
        if (Has(key_a)) {
          throw ConfigError::At(self_.file(), Get(key_b).line(), Prefix() + problem);
        }
      }
    }
  }

 private:
  [[nodiscard]] std::string Prefix() const {
    return self_.path().empty() ? "" : self_.path() + ": ";
  }

  Value self_;
  std::map<std::string, Value> entries_;
};

MapValue Value::Map(std::vector<std::string> known) const {
  return MapValue(*this, std::move(known));
}

std::vector<std::pair<std::string, Value>> Value::Entries() const {
  if (!node_.IsMap()) Fail("expected a map");
  std::vector<std::pair<std::string, Value>> out;
  std::map<std::string, int> first_line;
  for (const auto& kv : node_) {
    const int line = LineOf(kv.first);
    const std::string where = path_.empty() ? "" : path_ + ": ";
    if (!kv.first.IsScalar()) {
      throw ConfigError::At(*file_, line, where + "keys must be strings");
    }
    const std::string key = kv.first.Scalar();
    if (!first_line.emplace(key, line).second) {
      throw ConfigError::At(*file_, line, where + "duplicate key '" + key + "'");
    }
    out.emplace_back(key, Value(kv.second, path_.empty() ? key : path_ + "." + key, line, file_));
  }
  return out;
}

/// Reads the scene tree. Single-thread; one instance per file.
class SceneParser {
 public:
  SceneParser(const std::string& file, const std::string& base_dir)
      : file_(file), base_dir_(base_dir) {}

  Scene Parse(const YAML::Node& root) {
    const Value top(root, "", std::max(LineOf(root), 1), &file_);
    if (!root.IsMap()) {
      top.Fail("expected a map with the key 'scene' (see docs/scenes.md)");
    }
    const MapValue map = top.Map({"scene", "cameras", "capture_offsets_ms", "obstacles",
                                  "foreground_objects", "people", "imaging", "masks", "mounting"});
    Scene scene;
    ParseHeader(map.Get("scene"), &scene);
    if (const std::optional<Value> cameras = map.Find("cameras")) {
      if (!cameras->node().IsSequence() || cameras->node().size() == 0) {
        cameras->Fail("expected a non-empty list of cameras");
      }
      if (cameras->node().size() > static_cast<std::size_t>(common::kMaxCameras)) {
        cameras->Fail(std::to_string(cameras->node().size()) + " cameras, at most " +
                      std::to_string(common::kMaxCameras) +
                      " (one octree fuses at most that many)");
      }
      // Names become synth's folders (masks/<camera>/).
      for (geometry::CameraModel& model :
           geometry::ParseCameraList(cameras->node(), file_, /*file_names=*/true)) {
        scene.cameras.push_back(SceneCamera{std::move(model), 0.0});
      }
    }
    if (const std::optional<Value> offsets = map.Find("capture_offsets_ms")) {
      ParseOffsets(*offsets, &scene);
    }
    if (const std::optional<Value> obstacles = map.Find("obstacles")) {
      scene.obstacles = ParseSolids(*obstacles);
    }
    if (const std::optional<Value> objects = map.Find("foreground_objects")) {
      scene.foreground_objects = ParseSolids(*objects);
    }
    if (const std::optional<Value> people = map.Find("people")) {
      std::map<std::string, int> first_line;
      for (const Value& entry : people->List()) {
        const MapValue person_map = entry.Map(
            {"name", "height", "shirt", "trousers", "skin", "start", "heading_deg", "script"});
        Person person = ParsePerson(person_map);
        const Value& name = person_map.Get("name");
        const auto [it, inserted] = first_line.emplace(person.name, name.line());
        if (!inserted) {
          name.Fail("duplicate person name '" + person.name + "' (first at line " +
                    std::to_string(it->second) + ")");
        }
        scene.people.push_back(std::move(person));
      }
    }
    if (const std::optional<Value> imaging = map.Find("imaging")) {
      scene.imaging = ParseImaging(*imaging);
    }
    if (const std::optional<Value> mounting = map.Find("mounting")) {
      scene.mounting = ParseMounting(*mounting);
    }
    if (const std::optional<Value> masks = map.Find("masks")) {
      const MapValue masks_map = masks->Map({"occlusion"});
      if (const std::optional<Value> v = masks_map.Find("occlusion")) {
        scene.mask_occlusion = v->Bool();
      }
    }
    return scene;
  }

 private:
  void ParseHeader(const Value& value, Scene* scene) const {
    const MapValue map = value.Map({"name", "bounds", "rate_hz"});
    scene->name = map.Get("name").String();
    const MapValue bounds = map.Get("bounds").Map({"min", "max"});
    scene->bounds.min = bounds.Get("min").Vector3();
    scene->bounds.max = bounds.Get("max").Vector3();
    if (!scene->bounds.IsValid()) {
      bounds.Get("max").Fail("must be greater than min on every axis");
    }
    if (!scene->bounds.IsPlausibleCell()) {
      bounds.Get("max").Fail("coordinates must be within +-1e6 m");
    }
    if (const std::optional<Value> rate = map.Find("rate_hz")) {
      scene->rate_hz = rate->Positive();
      if (!(scene->rate_hz >= 0.1 && scene->rate_hz <= 1000.0)) {
        rate->Fail("must be within [0.1, 1000] Hz");
      }
    }
  }

  void ParseOffsets(const Value& value, Scene* scene) const {
    for (const auto& [name, offset] : value.Entries()) {
      SceneCamera* camera = nullptr;
      std::vector<std::string> names;
      for (SceneCamera& c : scene->cameras) {
        names.push_back(c.model.name);
        if (c.model.name == name) camera = &c;
      }
      if (camera == nullptr) {
        offset.Fail(
            "unknown camera '" + name + "'" +
            (names.empty() ? " (the scene has no cameras)" : " (cameras: " + Join(names) + ")"));
      }
      // Within a second either way, as a synth recording's manifest takes it.
      camera->time_offset_s = 1e-3 * offset.InRange(-1000.0, 1000.0);
    }
  }

  std::vector<Solid> ParseSolids(const Value& value) {
    std::vector<Solid> solids;
    for (const Value& entry : value.List()) {
      const MapValue map = entry.Map({"name", "colour", "box", "cylinder", "capsule", "mesh"});
      Solid solid;
      const Value& name = map.Get("name");
      solid.name = name.String();
      const auto [it, inserted] = solid_names_.emplace(solid.name, name.line());
      if (!inserted) {
        name.Fail("duplicate object name '" + solid.name + "' (first at line " +
                  std::to_string(it->second) + ")");
      }
      if (const std::optional<Value> colour = map.Find("colour")) {
        solid.colour = colour->Colour();
      }
      const std::string shape = map.OneOf({"box", "cylinder", "capsule", "mesh"});
      const Value& shape_value = map.Get(shape);
      if (shape == "box") {
        solid.geometry = ParseBox(shape_value);
      } else if (shape == "cylinder") {
        solid.geometry = ParseCylinder(shape_value);
      } else if (shape == "capsule") {
        solid.geometry = ParseCapsule(shape_value);
      } else {
        solid.geometry = ParseMesh(shape_value);
      }
      solids.push_back(std::move(solid));
    }
    return solids;
  }

  static BoxSolid ParseBox(const Value& value) {
    const MapValue map = value.Map({"min", "max", "centre", "size", "yaw_deg"});
    map.Exclusive({"min", "max"}, {"centre", "size", "yaw_deg"},
                  "give either min+max or centre+size (+yaw_deg), not both");
    BoxSolid box;
    if (map.Has("min") || map.Has("max")) {
      const Eigen::Vector3d min = map.Get("min").Vector3();
      const Eigen::Vector3d max = map.Get("max").Vector3();
      if (!(max.array() > min.array()).all()) {
        map.Get("max").Fail("must be greater than min on every axis");
      }
      box.centre_W = 0.5 * (min + max);
      box.half_extents_m = 0.5 * (max - min);
      return box;
    }
    box.centre_W = map.Get("centre").Vector3();
    box.half_extents_m = 0.5 * map.Get("size").PositiveVector3();
    if (const std::optional<Value> yaw = map.Find("yaw_deg")) {
      box.R_WB = Eigen::AngleAxisd(yaw->Degrees(), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    }
    return box;
  }

  static CylinderSolid ParseCylinder(const Value& value) {
    const MapValue map = value.Map({"base", "height", "a", "b", "radius"});
    map.Exclusive({"base", "height"}, {"a", "b"},
                  "give either base+height (vertical) or a+b, not both");
    CylinderSolid cylinder;
    cylinder.radius_m = map.Get("radius").Size();
    if (map.Has("a") || map.Has("b")) {
      cylinder.a_W = map.Get("a").Vector3();
      cylinder.b_W = map.Get("b").Vector3();
      if (cylinder.a_W == cylinder.b_W) map.Get("b").Fail("must differ from a");
      return cylinder;
    }
    cylinder.a_W = map.Get("base").Vector3();
    cylinder.b_W = cylinder.a_W + Eigen::Vector3d(0, 0, map.Get("height").Size());
    return cylinder;
  }

  static CapsuleSolid ParseCapsule(const Value& value) {
    const MapValue map = value.Map({"a", "b", "radius"});
    CapsuleSolid capsule;
    capsule.a_W = map.Get("a").Vector3();
    capsule.b_W = map.Get("b").Vector3();
    capsule.radius_m = map.Get("radius").Size();
    return capsule;
  }

  MeshSolid ParseMesh(const Value& value) const {
    const MapValue map = value.Map({"file", "translate", "yaw_deg", "scale"});
    const Value& file = map.Get("file");
    std::filesystem::path path(file.String());
    if (path.is_relative() && !base_dir_.empty()) path = std::filesystem::path(base_dir_) / path;
    MeshSolid solid;
    solid.file = file.String();
    solid.loaded_from = path.string();
    try {
      solid.mesh = geometry::LoadMesh(path.string());
    } catch (const ConfigError& e) {
      file.Fail(std::string("cannot load mesh: ") + e.what());
    }
    if (solid.mesh.triangles.empty()) {
      file.Fail("mesh has no triangles: " + path.string());
    }
    const double scale = map.Has("scale") ? map.Get("scale").Size() : 1.0;
    const double yaw = map.Has("yaw_deg") ? map.Get("yaw_deg").Degrees() : 0.0;
    const Eigen::Vector3d translate =
        map.Has("translate") ? map.Get("translate").Vector3() : Eigen::Vector3d::Zero();
    const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (Eigen::Vector3d& p : solid.mesh.vertices) {
      p = R * (scale * p) + translate;
    }
    return solid;
  }

  static Person ParsePerson(const MapValue& map) {
    Person person;
    person.name = map.Get("name").String();
    if (const std::optional<Value> v = map.Find("height")) person.height_m = v->InRange(1.0, 2.2);
    if (const std::optional<Value> v = map.Find("shirt")) person.shirt = v->Colour();
    if (const std::optional<Value> v = map.Find("trousers")) person.trousers = v->Colour();
    if (const std::optional<Value> v = map.Find("skin")) person.skin = v->Colour();
    person.start_W = map.Get("start").Point(0.0);
    if (const std::optional<Value> v = map.Find("heading_deg")) {
      person.start_heading_rad = v->Degrees();
    }
    if (const std::optional<Value> script = map.Find("script")) {
      Eigen::Vector3d position_W = person.start_W;
      double end_s = 0.0;
      for (const Value& item : script->List()) {
        person.actions.push_back(ParseAction(item, &position_W, &end_s));
      }
    }
    return person;
  }

  /// One script item. `position_W` is where the person stands when the
  /// action starts (updated to where it ends); `end_s` the end of the
  /// previous action (updated likewise).
  static Action ParseAction(const Value& item, Eigen::Vector3d* position_W, double* end_s) {
    const MapValue map = item.Map({"at", "walk", "stand", "crouch", "crawl", "reach"});
    const std::string kind = map.OneOf({"walk", "stand", "crouch", "crawl", "reach"});
    Action action;
    action.start_s = *end_s;
    if (const std::optional<Value> at = map.Find("at")) {
      const double start = at->NonNegative();
      if (start < *end_s) {
        at->Fail("must not be before the end of the previous action (" + FormatNumber(start) +
                 " s < " + FormatNumber(*end_s) + " s)");
      }
      action.start_s = start;
    }
    const Value& body = map.Get(kind);
    if (kind == "walk" || kind == "crawl") {
      action.kind = kind == "walk" ? ActionKind::kWalk : ActionKind::kCrawl;
      const MapValue m = body.Map({"path", "speed"});
      const Value& path = m.Get("path");
      const std::vector<Value> waypoints = path.List();
      if (waypoints.empty()) path.Fail("needs at least 1 waypoint");
      double length_m = 0.0;
      Eigen::Vector3d previous = *position_W;
      for (const Value& waypoint : waypoints) {
        const Eigen::Vector3d p = waypoint.Point(previous.z());
        length_m += (p - previous).norm();
        action.path_W.push_back(p);
        previous = p;
      }
      if (!(length_m > 0.0)) {
        path.Fail("has zero length (every waypoint is where the person already is)");
      }
      // A crawl at walking pace would be unphysical; the default is a slow crawl.
      action.speed_mps = action.kind == ActionKind::kWalk ? 1.2 : 0.4;
      // 1 cm/s at the least: a speed near zero made an action last for ever.
      if (const std::optional<Value> speed = m.Find("speed")) {
        action.speed_mps = speed->InRange(0.01, 10.0);
      }
      action.duration_s = length_m / action.speed_mps;
      *position_W = previous;
    } else if (kind == "stand" || kind == "crouch") {
      action.kind = kind == "stand" ? ActionKind::kStand : ActionKind::kCrouch;
      const MapValue m = body.Map({"duration", "heading_deg"});
      action.duration_s = m.Get("duration").Positive();
      if (const std::optional<Value> heading = m.Find("heading_deg")) {
        action.heading_rad = heading->Degrees();
      }
    } else {
      action.kind = ActionKind::kReach;
      const MapValue m = body.Map({"target", "hand", "duration"});
      action.target_W = m.Get("target").Vector3();
      if (const std::optional<Value> hand = m.Find("hand")) {
        const std::string side = hand->String();
        if (side != "left" && side != "right") hand->Fail("expected 'left' or 'right'");
        action.left_hand = side == "left";
      }
      action.duration_s = m.Get("duration").Positive();
    }
    *end_s = action.start_s + action.duration_s;
    if (!(*end_s <= kMaxSceneSeconds)) {
      item.Fail("ends at " + FormatNumber(*end_s) + " s, after the longest script (" +
                FormatNumber(kMaxSceneSeconds) + " s)");
    }
    return action;
  }

  /// The `mounting` list; an empty list is allowed (a cell with no place for
  /// a camera), so that camera placement can say so.
  static std::vector<MountingSurface> ParseMounting(const Value& value) {
    std::vector<MountingSurface> surfaces;
    std::map<std::string, int> first_line;
    for (const Value& entry : value.List()) {
      const MapValue map = entry.Map({"name", "wall", "ceiling", "pole"});
      MountingSurface surface;
      const Value& name = map.Get("name");
      surface.name = name.String();
      const auto [it, inserted] = first_line.emplace(surface.name, name.line());
      if (!inserted) {
        name.Fail("duplicate mounting surface name '" + surface.name + "' (first at line " +
                  std::to_string(it->second) + ")");
      }
      const std::string kind = map.OneOf({"wall", "ceiling", "pole"});
      const Value& body = map.Get(kind);
      if (kind == "wall") {
        const MapValue m = body.Map({"from", "to", "z"});
        const std::vector<double> from = m.Get("from").Numbers(2, 2);
        const std::vector<double> to = m.Get("to").Numbers(2, 2);
        if (from == to) m.Get("to").Fail("must differ from 'from'");
        const auto [z0, z1] = ZRange(m.Get("z"));
        surface.kind = MountingSurface::Kind::kWall;
        surface.origin_W = Eigen::Vector3d(from[0], from[1], z0);
        surface.u_W = Eigen::Vector3d(to[0] - from[0], to[1] - from[1], 0.0);
        surface.v_W = Eigen::Vector3d(0.0, 0.0, z1 - z0);
      } else if (kind == "ceiling") {
        const MapValue m = body.Map({"min", "max", "z"});
        const std::vector<double> min = m.Get("min").Numbers(2, 2);
        const std::vector<double> max = m.Get("max").Numbers(2, 2);
        if (!(max[0] > min[0] && max[1] > min[1])) {
          m.Get("max").Fail("must be greater than min on both axes");
        }
        surface.kind = MountingSurface::Kind::kCeiling;
        surface.origin_W = Eigen::Vector3d(min[0], min[1], m.Get("z").Number());
        surface.u_W = Eigen::Vector3d(max[0] - min[0], 0.0, 0.0);
        surface.v_W = Eigen::Vector3d(0.0, max[1] - min[1], 0.0);
      } else {
        const MapValue m = body.Map({"at", "z"});
        const std::vector<double> at = m.Get("at").Numbers(2, 2);
        const auto [z0, z1] = ZRange(m.Get("z"));
        surface.kind = MountingSurface::Kind::kPole;
        surface.origin_W = Eigen::Vector3d(at[0], at[1], z0);
        surface.u_W = Eigen::Vector3d(0.0, 0.0, z1 - z0);
      }
      surfaces.push_back(std::move(surface));
    }
    return surfaces;
  }

  /// [z_low, z_high] with z_high > z_low.
  static std::pair<double, double> ZRange(const Value& value) {
    const std::vector<double> z = value.Numbers(2, 2);
    if (!(z[1] > z[0])) value.Fail("expected [low, high] with high > low");
    return {z[0], z[1]};
  }

  static ImagingSettings ParseImaging(const Value& value) {
    const MapValue map = value.Map(
        {"noise_sigma", "light", "ambient", "shadows", "shadow_softness", "light_change", "seed"});
    ImagingSettings s;
    if (const std::optional<Value> v = map.Find("noise_sigma")) s.noise_sigma = v->NonNegative();
    if (const std::optional<Value> v = map.Find("light")) s.light_W = v->Vector3();
    if (const std::optional<Value> v = map.Find("ambient")) s.ambient = v->InRange(0.0, 1.0);
    if (const std::optional<Value> v = map.Find("shadows")) s.shadows = v->Bool();
    if (const std::optional<Value> v = map.Find("shadow_softness")) {
      s.shadow_softness_m = v->NonNegative();
    }
    if (const std::optional<Value> v = map.Find("light_change")) {
      const MapValue change = v->Map({"amplitude", "period_s"});
      if (const std::optional<Value> a = change.Find("amplitude")) {
        // The gain 1 + a sin(.) must stay positive.
        s.light_change_amplitude = a->NonNegative();
        if (!(s.light_change_amplitude < 1.0)) a->Fail("must be < 1");
      }
      if (const std::optional<Value> p = change.Find("period_s")) {
        s.light_change_period_s = p->Positive();
      }
    }
    if (const std::optional<Value> v = map.Find("seed")) s.seed = v->Unsigned();
    return s;
  }

  std::string file_;
  std::string base_dir_;
  /// Object name -> line of its first definition, over obstacles and
  /// foreground objects together.
  std::map<std::string, int> solid_names_;
};

}  // namespace

std::vector<geometry::CameraModel> Scene::CameraModels() const {
  std::vector<geometry::CameraModel> models;
  models.reserve(cameras.size());
  for (const SceneCamera& camera : cameras) {
    models.push_back(camera.model);
  }
  return models;
}

std::vector<geometry::TriangleMesh> Scene::ObstacleMeshes() const {
  std::vector<geometry::TriangleMesh> meshes;
  meshes.reserve(obstacles.size());
  for (const Solid& obstacle : obstacles) {
    meshes.push_back(Tessellate(obstacle.geometry));
  }
  return meshes;
}

Scene LoadScene(const std::string& path) {
  const std::string text = common::ReadInputFile(path, "");
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  Scene scene = ParseScene(text, path, base_dir);
  scene.source_file = path;
  return scene;
}

Scene ParseScene(const std::string& yaml_text, const std::string& file,
                 const std::string& base_dir) {
  return SceneParser(file, base_dir).Parse(common::ParseYaml(yaml_text, file));
}

}  // namespace hg::sim
