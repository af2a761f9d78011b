#include "geometry/camera_yaml.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <system_error>
#include <utility>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include "common/config_error.h"
#include "common/limits.h"
#include "common/yaml_file.h"
#include "geometry/footprint.h"

namespace hg::geometry {
namespace {

using common::ConfigError;

/// yaml-cpp marks are 0-based; messages use 1-based lines (0 = unknown, omitted).
int LineOf(const YAML::Node& node) { return common::YamlLine(node); }

/// Largest image side: the undistorter stores pixel indices in 16 bits and
/// reserves 0xFFFF.
constexpr int kMaxImageSide = 65535;

/// |R^T R - I| (Frobenius) above this is not a rotation; loose enough for
/// matrices written with ~6 significant digits.
constexpr double kRotationTolerance = 1e-5;

/// `look_at` closer than this to `position` gives no usable viewing direction (m).
constexpr double kMinLookDistance = 1e-9;

/// |cos| of the angle between the viewing direction and `up` above which `up`
/// cannot orient the image (about 8 degrees); the same limit as the demo cell.
constexpr double kMaxUpAlignment = 0.99;

/// Plausible cameras (CheckPlausible): focal lengths in pixels, coordinates in
/// metres, distortion coefficients.
constexpr double kMinFocalPx = 1.0;
constexpr double kMaxFocalPx = 1e6;
constexpr double kMaxDistortion = 1000.0;

/// Reads one camera entry. `where` names the entry in messages ("cameras[2]"),
/// empty for a stand-alone entry.
class CameraParser {
 public:
  /// With `errors`, the independent checks each record their problem there and
  /// parsing goes on; without, the first problem is thrown.
  CameraParser(const YAML::Node& node, const std::string& file, std::string where,
               std::vector<std::string>* errors = nullptr)
      : node_(node), file_(file), where_(std::move(where)), errors_(errors) {}

  CameraModel Parse() {
    const std::size_t errors_before = errors_ != nullptr ? errors_->size() : 0;
    CameraModel camera = ParseForms();
    const bool parsed = errors_ == nullptr || errors_->size() == errors_before;
    if (parsed) Check([&] { CheckPlausible(camera); });
    return camera;
  }

  /// Line of the `name` key; valid after Parse() returned.
  [[nodiscard]] int name_line() const { return LineOf(Key("name")); }

 private:
  CameraModel ParseForms() {
    if (!node_.IsMap()) {
      throw ConfigError::At(file_, LineOf(node_), Prefix() + "expected a map with the camera keys");
    }
    static const std::set<std::string> kKnown = {
        "name", "width", "height", "K", "R", "t", "P", "distortion", "position", "look_at", "up"};
    for (const auto& kv : node_) {
      Check([&] {
        const int line = LineOf(kv.first);
        if (!kv.first.IsScalar()) {
          throw ConfigError::At(file_, line, Prefix() + "keys must be strings");
        }
        const std::string key = kv.first.Scalar();
        if (key == "<<") throw ConfigError::At(file_, line, Prefix() + common::kMergeKeyText);
        if (kKnown.count(key) == 0) {
          throw ConfigError::At(file_, line, Prefix() + "unknown key '" + key + "'");
        }
        if (!keys_.emplace(key, kv).second) {
          throw ConfigError::At(file_, line, Prefix() + "duplicate key '" + key + "'");
        }
      });
    }

    CameraModel camera;
    Check([&] { camera.name = ParseName(); });
    // Full HD unless given.
    Check([&] { camera.width = ParseSide("width", 1920); });
    Check([&] { camera.height = ParseSide("height", 1080); });
    Check([&] {
      if (camera.width > 0 && camera.height > 0 &&
          !common::ImageFits(camera.width, camera.height)) {
        throw ConfigError::At(file_, Has("width") ? LineOf(Key("width")) : LineOf(node_),
                              Path("width") + ": an image of " + std::to_string(camera.width) +
                                  " x " + std::to_string(camera.height) +
                                  " pixels is too large (at most 2^20 tiles of 8 x 8 pixels, "
                                  "about 8000 x 8000)");
      }
    });

    const bool has_p = Has("P");
    const bool has_krt = Has("K") || Has("R") || Has("t");
    const bool has_look_at = Has("position") || Has("look_at") || Has("up");
    bool one_form = false;  // Past a mix of forms, the projection is not checked further.
    Check([&] {
      if (has_p && has_krt) {
        throw ConfigError::At(file_, LineOf(Key("P")),
                              Prefix() + "give either K+R+t or P, not both");
      }
      if (has_p && has_look_at) {
        throw ConfigError::At(file_, LineOf(Key("P")),
                              Prefix() + "give either K+position+look_at or P, not both");
      }
      if (has_look_at && (Has("R") || Has("t"))) {
        const std::string key = Has("R") ? "R" : "t";
        throw ConfigError::At(file_, LineOf(Key(key)),
                              Prefix() + "give either R+t or position+look_at (+up), not both");
      }
      one_form = true;
    });
    if (Has("distortion")) {
      Check([&] {
        const std::vector<double> d = Numbers("distortion", 5);
        for (int i = 0; i < 5; ++i) {
          camera.distortion[i] = d[i];
        }
      });
    }
    if (!one_form) return camera;  // Only when collecting: the mix is recorded.
    if (has_p) {
      Check([&] {
        const std::vector<double> p = Numbers("P", 12);
        Eigen::Matrix<double, 3, 4> P;
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 4; ++c) {
            P(r, c) = p[4 * r + c];
          }
        }
        std::string error;
        const std::optional<DecomposeResult> krt = DecomposeProjection(P, &error);
        if (!krt) {
          throw ConfigError::At(file_, LineOf(Key("P")), Path("P") + ": " + error);
        }
        camera.K = krt->K;
        camera.R_CW = krt->R_CW;
        camera.t_CW = krt->t_CW;
      });
      return camera;
    }
    if (has_look_at) {
      for (const char* key : {"K", "position", "look_at"}) {
        Check([&] { Require(key); });
      }
      if (Has("K")) {
        Check([&] {
          camera.K = Matrix3("K");
          CheckIntrinsics(camera.K);
        });
      }
      if (Has("position") && Has("look_at")) Check([&] { SetLookAtPose(&camera); });
      return camera;
    }
    for (const char* key : {"K", "R", "t"}) {
      Check([&] { Require(key); });
    }
    bool k_read = false;
    bool r_read = false;
    if (Has("K")) {
      Check([&] {
        camera.K = Matrix3("K");
        k_read = true;
      });
    }
    if (Has("R")) {
      Check([&] {
        camera.R_CW = Matrix3("R");
        r_read = true;
      });
    }
    if (Has("t")) {
      Check([&] {
        const std::vector<double> t = Numbers("t", 3);
        camera.t_CW = Eigen::Vector3d(t[0], t[1], t[2]);
      });
    }
    if (k_read) Check([&] { CheckIntrinsics(camera.K); });
    if (r_read) Check([&] { CheckRotation(camera.R_CW); });
    return camera;
  }

  /// Numbers no real camera has: a focal length of a thousandth of a pixel
  /// would see the whole cell in one pixel and certify it free at once.
  void CheckPlausible(const CameraModel& camera) const {
    const std::string intrinsics = Has("P") ? "P" : "K";
    auto fail = [&](const std::string& key, const std::string& problem) {
      throw ConfigError::At(file_, Has(key) ? LineOf(Key(key)) : LineOf(node_),
                            Path(key) + ": " + problem);
    };
    const Eigen::Matrix3d& K = camera.K;
    if (!(K(0, 0) >= kMinFocalPx && K(0, 0) <= kMaxFocalPx && K(1, 1) >= kMinFocalPx &&
          K(1, 1) <= kMaxFocalPx)) {
      char got[96];
      std::snprintf(got, sizeof(got), " (got %.6g, %.6g)", K(0, 0), K(1, 1));
      fail(intrinsics, std::string("focal lengths must be within [1, 1e6] px") + got);
    }
    if (!(K(0, 0) <= kMaxFocalAspect * K(1, 1) && K(1, 1) <= kMaxFocalAspect * K(0, 0))) {
      char problem[128];
      std::snprintf(problem, sizeof(problem),
                    "focal lengths more than %g times apart (got %.6g, %.6g)", kMaxFocalAspect,
                    K(0, 0), K(1, 1));
      fail(intrinsics, problem);
    }
    if (!(std::abs(K(0, 1)) <= K(0, 0))) fail(intrinsics, "skew larger than the focal length");
    if (!(K(0, 2) >= -camera.width && K(0, 2) <= 2.0 * camera.width && K(1, 2) >= -camera.height &&
          K(1, 2) <= 2.0 * camera.height)) {
      fail(intrinsics, "principal point more than an image size outside the image");
    }
    const double reach_u = std::max(std::abs(K(0, 2)), std::abs(camera.width - K(0, 2))) / K(0, 0);
    const double reach_v = std::max(std::abs(K(1, 2)), std::abs(camera.height - K(1, 2))) / K(1, 1);
    if (!(reach_u <= kMaxImageReach && reach_v <= kMaxImageReach)) {
      char problem[160];
      std::snprintf(problem, sizeof(problem),
                    "the image reaches %.6g focal lengths from the principal point (at most %g: "
                    "a view wider than any pinhole lens)",
                    std::max(reach_u, reach_v), kMaxImageReach);
      fail(intrinsics, problem);
    }
    const Eigen::Vector3d centre = camera.CentreW();
    if (!(centre.lpNorm<Eigen::Infinity>() <= common::kMaxCoordinateM)) {
      const std::string key = Has("P") ? "P" : Has("position") ? "position" : "t";
      fail(key, "camera position more than 1e6 m from the origin");
    }
    for (int i = 0; i < 5; ++i) {
      if (!(std::abs(camera.distortion[i]) <= kMaxDistortion)) {
        fail("distortion", "coefficients must be within [-1000, 1000]");
      }
    }
  }

  /// Runs one check that does not depend on the others having passed: when
  /// collecting, its problem is recorded and parsing goes on.
  template <typename F>
  void Check(F&& check) {
    if (errors_ == nullptr) {
      check();
      return;
    }
    try {
      check();
    } catch (const ConfigError& e) {
      errors_->emplace_back(e.what());
    }
  }

  [[nodiscard]] std::string Prefix() const { return where_.empty() ? "" : where_ + ": "; }
  [[nodiscard]] std::string Path(const std::string& key) const {
    return where_.empty() ? key : where_ + "." + key;
  }
  [[nodiscard]] bool Has(const std::string& key) const { return keys_.count(key) != 0; }
  [[nodiscard]] const YAML::Node& Key(const std::string& key) const { return keys_.at(key).first; }
  [[nodiscard]] const YAML::Node& Value(const std::string& key) const {
    return keys_.at(key).second;
  }
  void Require(const std::string& key) const {
    if (!Has(key)) {
      throw ConfigError::At(file_, LineOf(node_), Prefix() + "missing key '" + key + "'");
    }
  }

  std::string ParseName() const {
    Require("name");
    const YAML::Node& v = Value("name");
    if (!v.IsScalar() || v.Scalar().empty()) {
      throw ConfigError::At(file_, LineOf(Key("name")),
                            Path("name") + ": expected a non-empty string");
    }
    const std::string& name = v.Scalar();
    return name;
  }

  int ParseSide(const std::string& key, int absent) const {
    if (!Has(key)) return absent;
    const YAML::Node& v = Value(key);
    int side = 0;
    bool ok = v.IsScalar() && v.Tag() != "!";  // "!": a quoted string.
    if (ok) {
      // Decimal digits only: yaml-cpp reads 02000 as octal (1024) and 0x780
      // as hex, neither what a calibration file means.
      const std::string& text = v.Scalar();
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), side);
      ok = ec == std::errc() && end == text.data() + text.size() && !text.empty() &&
           (text.size() == 1 || text[0] != '0');
    }
    if (!ok || side <= 0 || side > kMaxImageSide) {
      throw ConfigError::At(file_, LineOf(Key(key)),
                            Path(key) + ": expected a positive integer (at most " +
                                std::to_string(kMaxImageSide) + ")");
    }
    return side;
  }

  std::vector<double> Numbers(const std::string& key, std::size_t count) const {
    const YAML::Node& v = Value(key);
    const int line = LineOf(Key(key));
    if (!v.IsSequence()) {
      throw ConfigError::At(
          file_, line, Path(key) + ": expected a list of " + std::to_string(count) + " numbers");
    }
    if (v.size() != count) {
      throw ConfigError::At(file_, line,
                            Path(key) + ": expected " + std::to_string(count) + " numbers, got " +
                                std::to_string(v.size()));
    }
    std::vector<double> out(count);
    for (std::size_t i = 0; i < count; ++i) {
      const YAML::Node& e = v[i];
      const std::string at = Path(key) + "[" + std::to_string(i) + "]";
      bool ok = e.IsScalar();
      if (ok) {
        try {
          out[i] = e.as<double>();
        } catch (const YAML::Exception&) {
          ok = false;
        }
      }
      if (!ok) {
        throw ConfigError::At(file_, LineOf(e), at + ": not a number");
      }
      if (!std::isfinite(out[i])) {
        throw ConfigError::At(file_, LineOf(e), at + ": not finite");
      }
    }
    return out;
  }

  Eigen::Matrix3d Matrix3(const std::string& key) const {
    const std::vector<double> m = Numbers(key, 9);
    Eigen::Matrix3d out;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        out(r, c) = m[3 * r + c];
      }
    }
    return out;
  }

  Eigen::Vector3d Vector3(const std::string& key) const {
    const std::vector<double> v = Numbers(key, 3);
    return {v[0], v[1], v[2]};
  }

  /// Pose from `position`, `look_at` and `up`: the camera sits at `position`, its
  /// optical axis (z) points at `look_at`, x points right and y down in the image,
  /// so that `up` appears upwards. Without `up`, +z is up, and +y for views within
  /// ~8 degrees of vertical, where +z gives no usable image direction.
  void SetLookAtPose(CameraModel* camera) const {
    const Eigen::Vector3d eye = Vector3("position");
    const Eigen::Vector3d target = Vector3("look_at");
    // Checked here, not only on the camera centre: beyond this the norms
    // below overflow and the pose comes out as R = 0, t = 0.
    for (const auto& [key, p] : {std::pair{"position", eye}, std::pair{"look_at", target}}) {
      if (!(p.lpNorm<Eigen::Infinity>() <= common::kMaxCoordinateM)) {
        throw ConfigError::At(file_, LineOf(Key(key)),
                              Path(key) + ": more than 1e6 m from the origin");
      }
    }
    const Eigen::Vector3d view = target - eye;
    if (!(view.norm() > kMinLookDistance)) {
      throw ConfigError::At(file_, LineOf(Key("look_at")),
                            Path("look_at") + ": must differ from position");
    }
    const Eigen::Vector3d forward = view.normalized();
    Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
    if (Has("up")) {
      up = Vector3("up");
      if (!(up.norm() > 0.0) || !(up.lpNorm<Eigen::Infinity>() <= common::kMaxCoordinateM)) {
        throw ConfigError::At(file_, LineOf(Key("up")),
                              Path("up") + ": must not be zero, nor longer than 1e6");
      }
      up.normalize();
      if (std::abs(forward.dot(up)) > kMaxUpAlignment) {
        throw ConfigError::At(file_, LineOf(Key("up")),
                              Path("up") + ": (nearly) parallel to the viewing direction");
      }
    } else if (std::abs(forward.dot(up)) > kMaxUpAlignment) {
      up = Eigen::Vector3d::UnitY();
    }
    const Eigen::Vector3d right = forward.cross(up).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    camera->R_CW.row(0) = right.transpose();
    camera->R_CW.row(1) = down.transpose();
    camera->R_CW.row(2) = forward.transpose();
    camera->t_CW = -camera->R_CW * eye;
  }

  void CheckIntrinsics(const Eigen::Matrix3d& K) const {
    if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0) {
      throw ConfigError::At(file_, LineOf(Key("K")),
                            Path("K") + ": must be upper triangular with a last row of 0 0 1");
    }
    if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0)) {
      throw ConfigError::At(file_, LineOf(Key("K")),
                            Path("K") + ": focal lengths K[0] and K[4] must be positive");
    }
  }

  void CheckRotation(const Eigen::Matrix3d& R) const {
    const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
    if (!(err <= kRotationTolerance) || !(R.determinant() > 0.0)) {
      char buf[160];
      std::snprintf(buf, sizeof(buf), ": R is not a rotation (|R^T R - I| = %.3g, det R = %.6g)",
                    err, R.determinant());
      throw ConfigError::At(file_, LineOf(Key("R")), Path("R") + buf);
    }
  }

  const YAML::Node& node_;
  const std::string& file_;
  std::string where_;
  std::vector<std::string>* errors_;  ///< Null: the first problem is thrown.
  // Key name -> (key node, value node), in document order of first appearance.
  std::map<std::string, std::pair<YAML::Node, YAML::Node>> keys_;
};

}  // namespace

CameraModel ParseCamera(const YAML::Node& node, const std::string& file) {
  return CameraParser(node, file, "").Parse();
}

std::optional<CameraModel> ParseCameraReportingAll(const YAML::Node& node, const std::string& file,
                                                   std::vector<std::string>* errors) {
  const std::size_t before = errors->size();
  try {
    CameraModel camera = CameraParser(node, file, "", errors).Parse();
    if (errors->size() == before) return camera;
  } catch (const ConfigError& e) {  // Not a map: nothing else to check.
    errors->emplace_back(e.what());
  }
  return std::nullopt;
}

std::string FileNameProblem(const std::string& name) {
  const bool safe =
      !name.empty() && name.front() != '.' && std::all_of(name.begin(), name.end(), [](char ch) {
        return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
               ch == '_' || ch == '-' || ch == '.';
      });
  if (safe) return "";
  return "'" + name +
         "' cannot name the camera's files and folders: letters, digits, '_', '-' and '.', not "
         "starting with '.'";
}

std::vector<CameraModel> ParseCameraList(const YAML::Node& node, const std::string& file,
                                         bool file_names) {
  if (!node.IsSequence() || node.size() == 0) {
    throw ConfigError::At(file, node.IsDefined() ? LineOf(node) : 0,
                          "cameras: expected a non-empty list of cameras");
  }
  std::vector<CameraModel> cameras;
  std::map<std::string, int> first_line;  // Camera name -> line of its entry.
  for (std::size_t i = 0; i < node.size(); ++i) {
    const YAML::Node entry = node[i];
    const std::string where = "cameras[" + std::to_string(i) + "]";
    CameraParser parser(entry, file, where);
    CameraModel camera = parser.Parse();
    const int line = parser.name_line();
    if (file_names) {
      if (const std::string problem = FileNameProblem(camera.name); !problem.empty()) {
        throw ConfigError::At(file, line, where + ".name: " + problem);
      }
    }
    const auto [it, inserted] = first_line.emplace(camera.name, line);
    if (!inserted) {
      throw ConfigError::At(file, line,
                            where + ".name: duplicate camera name '" + camera.name +
                                "' (first at line " + std::to_string(it->second) + ")");
    }
    cameras.push_back(std::move(camera));
  }
  return cameras;
}

std::vector<CameraModel> LoadCamerasFile(const std::string& path) {
  const YAML::Node root = common::LoadYamlFile(path);
  if (!root.IsMap()) {
    throw ConfigError::At(path, root.IsDefined() ? LineOf(root) : 0,
                          "expected a map with the single key 'cameras'");
  }
  YAML::Node cameras;
  bool found = false;
  for (const auto& kv : root) {
    const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
    if (key != "cameras") {
      throw ConfigError::At(path, LineOf(kv.first), "unknown key '" + key + "'");
    }
    if (found) {
      throw ConfigError::At(path, LineOf(kv.first), "duplicate key 'cameras'");
    }
    found = true;
    cameras = kv.second;
  }
  if (!found) {
    throw ConfigError::At(path, LineOf(root), "missing key 'cameras'");
  }
  return ParseCameraList(cameras, path);
}

void WriteCamerasFile(const std::string& path, const std::vector<CameraModel>& cameras) {
  YAML::Emitter out;
  // 17 significant digits make every double read back bit for bit.
  out.SetDoublePrecision(std::numeric_limits<double>::max_digits10);
  out << YAML::BeginMap << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  auto flow = [&out](const auto& values) {
    out << YAML::Flow << YAML::BeginSeq;
    for (double v : values) {
      out << v;
    }
    out << YAML::EndSeq;
  };
  for (const CameraModel& c : cameras) {
    out << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << c.name;
    out << YAML::Key << "width" << YAML::Value << c.width;
    out << YAML::Key << "height" << YAML::Value << c.height;
    std::vector<double> k;
    std::vector<double> r;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        k.push_back(c.K(i, j));
        r.push_back(c.R_CW(i, j));
      }
    }
    out << YAML::Key << "K" << YAML::Value;
    flow(k);
    out << YAML::Key << "distortion" << YAML::Value;
    flow(c.distortion);
    out << YAML::Key << "R" << YAML::Value;
    flow(r);
    out << YAML::Key << "t" << YAML::Value;
    flow(std::vector<double>{c.t_CW.x(), c.t_CW.y(), c.t_CW.z()});
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  common::WriteYamlFile(path, out);
}

}  // namespace hg::geometry
