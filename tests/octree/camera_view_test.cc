// The footprints a camera view computes, against an independent projection of
// the box corners; the static obstacle relation of a box: the verdict it gives
// equals the one looked up directly, and a clear or a behind box passes that on
// to its sub-boxes.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "geometry/footprint.h"
#include "octree/camera_view.h"
#include "octree/octree.h"
#include "silhouette/quadtree.h"
#include "support/random_scene.h"

namespace hg::octree {
namespace {

// A random pinhole camera: any rotation, centre within 4 m of the origin,
// focal lengths 50 .. 2000 px, principal point anywhere near the image, some
// skew, image 16 .. 1920 px wide.
geometry::CameraModel RandomCamera(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  geometry::CameraModel cam;
  cam.width = 16 + static_cast<int>(u01(rng) * 1904);
  cam.height = 16 + static_cast<int>(u01(rng) * 1064);
  const double fx = 50.0 + 1950.0 * u01(rng);
  cam.K << fx, (u01(rng) < 0.3 ? 0.05 * fx * (u01(rng) - 0.5) : 0.0),
      cam.width * (1.5 * u01(rng) - 0.25), 0.0, fx * (0.8 + 0.4 * u01(rng)),
      cam.height * (1.5 * u01(rng) - 0.25), 0.0, 0.0, 1.0;
  cam.R_CW =
      Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized().matrix();
  const Eigen::Vector3d centre_W =
      Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5) * 8.0;
  cam.t_CW = -cam.R_CW * centre_W;
  return cam;
}

// The pixel holding image coordinate x (pixel u covers [u - 0.5, u + 0.5)),
// clamped at +-1e9 as the engine does far outside any image.
int PixelOfCoordinate(double x) {
  return static_cast<int>(std::floor(std::clamp(x + 0.5, -1e9, 1e9)));
}

// Distance (px) from x to the nearest pixel border (x + 0.5 an integer).
double ToPixelBorder(double x) { return std::abs(x + 0.5 - std::round(x + 0.5)); }

// BoxProjector::Project (through CameraView, as the octree uses it) against an
// independent projection of the 8 corners from K, R, t with plain Eigen
// arithmetic. The footprint must be the same integer rectangle: the engine
// widens the corners' range by kFootprintSlackPx before rounding, so one of its
// bounds may lie one pixel further out exactly where the matching extreme
// corner lies within that slack (plus rounding) of a pixel border, never
// elsewhere, and never one pixel further in.
TEST(BoxProjectorTest, FootprintEqualsIndependentCornerProjection) {
  using Side = geometry::Footprint::Side;
  constexpr double kBorderBand = geometry::kFootprintSlackPx + 1e-8;
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int compared = 0, exact = 0, widened = 0, behind = 0, straddling = 0;
  for (int camera = 0; camera < 300; ++camera) {
    const geometry::CameraModel cam = RandomCamera(rng);
    const CameraView view(cam, {});
    for (int trial = 0; trial < 40; ++trial) {
      // Boxes of 1 mm .. 3 m anywhere around the camera; every second one has a
      // corner placed on a pixel border (back-projected from u or v = k + 0.5),
      // where the engine and the independent projection may round apart, or
      // 1e-9 .. 1e-2 px to either side of one, where the slack may widen the
      // rectangle (within 1e-6 px) or must not.
      const Eigen::Vector3d size =
          Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).unaryExpr([](double t) {
            return std::pow(10.0, -3.0 + 3.5 * t);
          });
      Eigen::Vector3d lo = Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5) * 12.0;
      if (trial % 2 == 1) {
        const double depth = 0.1 + 6.0 * u01(rng);
        const double offset =
            trial % 8 < 4 ? 0.0 : (u01(rng) < 0.5 ? -1 : 1) * std::pow(10.0, -9.0 + 7.0 * u01(rng));
        double u = -0.5 + std::floor(u01(rng) * (cam.width + 1)) + offset;
        double v = cam.height * u01(rng);
        if (trial % 4 == 3) std::swap(u, v);  // A v border instead (v may leave the image).
        const Eigen::Vector3d p_C = depth * (cam.K.inverse() * Eigen::Vector3d(u, v, 1.0));
        const Eigen::Vector3d p_W = cam.R_CW.transpose() * (p_C - cam.t_CW);
        // The corner on the border is the box's lower or its upper corner.
        lo = u01(rng) < 0.5 ? p_W : Eigen::Vector3d(p_W - size);
      }
      const Eigen::Vector3d hi = lo + size;
      const geometry::Footprint fp = view.projector().Project(lo, hi);

      double z_min = 0, z_max = 0, u_min = 0, u_max = 0, v_min = 0, v_max = 0;
      for (int i = 0; i < 8; ++i) {
        const Eigen::Vector3d p_W((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                                  (i & 4) ? hi.z() : lo.z());
        const Eigen::Vector3d p_C = cam.R_CW * p_W + cam.t_CW;
        const Eigen::Vector3d uvw = cam.K * p_C;
        const double z = p_C.z(), u = uvw.x() / z, v = uvw.y() / z;
        z_min = i == 0 ? z : std::min(z_min, z);
        z_max = i == 0 ? z : std::max(z_max, z);
        u_min = i == 0 ? u : std::min(u_min, u);
        u_max = i == 0 ? u : std::max(u_max, u);
        v_min = i == 0 ? v : std::min(v_min, v);
        v_max = i == 0 ? v : std::max(v_max, v);
      }
      const auto where = [&] {
        return ::testing::Message() << "camera " << camera << " trial " << trial << " box ["
                                    << lo.transpose() << "] .. [" << hi.transpose() << "]";
      };
      ASSERT_NEAR(fp.z_near, z_min, 1e-9 * (1.0 + std::abs(z_min))) << where();
      ASSERT_NEAR(fp.z_far, z_max, 1e-9 * (1.0 + std::abs(z_max))) << where();
      // Sides, away from the thresholds (no random box comes within 1e-9 of them).
      if (std::abs(z_max) < 1e-9 || std::abs(z_min - geometry::kMinFrontDepth) < 1e-9) continue;
      const Side side = z_max <= 0.0                        ? Side::kBehind
                        : z_min <= geometry::kMinFrontDepth ? Side::kStraddling
                                                            : Side::kInFront;
      ASSERT_EQ(fp.side, side) << where();
      behind += side == Side::kBehind;
      straddling += side == Side::kStraddling;
      // Rectangles of boxes at least 1 cm in front, where both projections
      // agree to far better than the band.
      if (side != Side::kInFront || z_min < 0.01) continue;
      ++compared;
      const geometry::PixelRect& r = fp.rect;
      const int want[4] = {PixelOfCoordinate(u_min), PixelOfCoordinate(v_min),
                           PixelOfCoordinate(u_max), PixelOfCoordinate(v_max)};
      const int got[4] = {r.u0, r.v0, r.u1, r.v1};
      const double extreme[4] = {u_min, v_min, u_max, v_max};
      bool all_equal = true;
      for (int b = 0; b < 4; ++b) {
        if (got[b] == want[b]) continue;
        all_equal = false;
        const int outwards = b < 2 ? -1 : 1;  // Lower bounds grow down, upper ones up.
        ASSERT_EQ(got[b], want[b] + outwards)
            << where() << " bound " << b << " at " << extreme[b] << ": engine " << got[b]
            << ", independent " << want[b];
        ASSERT_LE(ToPixelBorder(extreme[b]), kBorderBand)
            << where() << " bound " << b << " at " << extreme[b] << " widened off a border";
      }
      exact += all_equal;
      widened += !all_equal;
    }
  }
  // Thousands of rectangles compared, the border case met, and the widening rare.
  EXPECT_GT(compared, 5000);
  EXPECT_GT(widened, 100);
  EXPECT_GT(exact, 4 * widened);
  EXPECT_GT(behind, 100);
  EXPECT_GT(straddling, 100);
}

// The pixel holding the exact projection of row r of P at p_W (pixel u
// covers [u - 0.5, u + 0.5)): products and sums of doubles in 113-bit
// arithmetic, exact to far below a pixel at any coordinates here.
long long ExactPixel(const Eigen::Matrix<double, 3, 4>& P, int r, const Eigen::Vector3d& p_W) {
  __float128 num = P(r, 3), den = P(2, 3);
  for (int a = 0; a < 3; ++a) {
    num += static_cast<__float128>(P(r, a)) * p_W[a];
    den += static_cast<__float128>(P(2, a)) * p_W[a];
  }
  const __float128 x = num / den + static_cast<__float128>(0.5);
  long long pixel = static_cast<long long>(x);  // Towards zero.
  if (static_cast<__float128>(pixel) > x) --pixel;
  return pixel;
}

// A footprint holds the pixel of every corner's exact projection, also where
// the cell lies a million metres from the origin (a site frame) with long
// focal lengths and boxes close to the lens: projected as P (x, 1), terms of
// 1e11 cancelled and the rounding error (1e-4 px) exceeded the slack, so a box
// was freed by a pixel it touches. The first case is such a box, found by an
// audit: its lower corner projects 3.7e-5 px left of the border between
// pixels 755 and 756.
TEST(BoxProjectorTest, FootprintHoldsTheExactCornerPixelsFarFromTheOrigin) {
  int checked = 0;
  auto check = [&](const Eigen::Matrix<double, 3, 4>& P, const Eigen::Vector3d& lo,
                   const Eigen::Vector3d& hi, const char* what) {
    const geometry::Footprint fp = geometry::BoxProjector(P).Project(lo, hi);
    if (fp.side != geometry::Footprint::Side::kInFront) return;
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p_W((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                                (i & 4) ? hi.z() : lo.z());
      const long long u = ExactPixel(P, 0, p_W), v = ExactPixel(P, 1, p_W);
      ++checked;
      ASSERT_TRUE(fp.rect.u0 <= u && u <= fp.rect.u1 && fp.rect.v0 <= v && v <= fp.rect.v1)
          << what << ": corner " << i << " in pixel (" << u << ", " << v << "), footprint ["
          << fp.rect.u0 << ", " << fp.rect.u1 << "] x [" << fp.rect.v0 << ", " << fp.rect.v1
          << "], box [" << lo.transpose() << "] .. [" << hi.transpose() << "]";
    }
  };
  {
    Eigen::Matrix<double, 3, 4> P;
    P << 1e5, 0, 2000, 2000 * 0.0 - 1e5 * 999999.0, 0, 1e5, 1100, 0, 0, 0, 1, 0;
    const common::Box3 bounds{{999998.9991, -0.0005, 0.05}, {999998.99999, 0.0005, 0.06}};
    const common::Box3 cell = CellBox(bounds, {10, 227, 512, 662});
    check(P, cell.min, cell.max, "the audit's cell");
  }
  // Random cameras a million metres out, focal lengths 1e3 .. 1e5 px, boxes
  // of 1 um .. 10 cm at 5 cm .. 5 m in front, half of them with a corner on
  // a pixel border.
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int camera = 0; camera < 200; ++camera) {
    const double f = std::pow(10.0, 3.0 + 2.0 * u01(rng));
    Eigen::Matrix3d K;
    K << f, 0, 1000 * u01(rng), 0, f * (0.9 + 0.2 * u01(rng)), 1000 * u01(rng), 0, 0, 1;
    const Eigen::Matrix3d R = Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng))
                                  .normalized()
                                  .matrix();
    const Eigen::Vector3d centre_W(1e6 * (0.5 + 0.5 * u01(rng)), -1e6 * u01(rng), 100 * u01(rng));
    Eigen::Matrix<double, 3, 4> Rt;
    Rt.leftCols<3>() = R;
    Rt.col(3) = -R * centre_W;
    const Eigen::Matrix<double, 3, 4> P = K * Rt;
    for (int trial = 0; trial < 50; ++trial) {
      const double depth = std::pow(10.0, -1.3 + 2.0 * u01(rng));
      const Eigen::Vector3d size =
          Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).unaryExpr([](double t) {
            return std::pow(10.0, -6.0 + 5.0 * t);
          });
      double u = 1000 * u01(rng), v = 1000 * u01(rng);
      if (trial % 2 == 1) u = std::floor(u) + 0.5;
      const Eigen::Vector3d p_C = depth * (K.inverse() * Eigen::Vector3d(u, v, 1.0));
      const Eigen::Vector3d corner = R.transpose() * p_C + centre_W;
      const Eigen::Vector3d lo = u01(rng) < 0.5 ? corner : Eigen::Vector3d(corner - size);
      check(P, lo, lo + size, "random");
      if (HasFatalFailure()) return;
    }
  }
  EXPECT_GT(checked, 50000);
}

// The projection's rounding error, against the calibrated camera K (R p + t)
// itself, stays far below kFootprintSlackPx at the edges of what the camera loader accepts
// (camera_yaml.cc, CheckPlausible): focal lengths 1 .. 1e6 px at most kMaxFocalAspect apart, skew
// up to the focal length, the principal point up to an image size outside images up to 65535 px
// that reach at most kMaxImageReach focal lengths from it, cameras a million metres from the
// origin, points 5 cm .. 5 m in front. Only points that project into the image count: a footprint's
// border inside the image is the projection of such a point. The error grows with the ratio of the
// focal lengths (a point in view at v / fy = 65535 is far off the axis in units of fx): at 1e6,
// which the loader used to accept, it reached 2e-5 px, twenty times the slack. Projected with K [R
// | t] multiplied out in doubles, the rounding of K t moved the camera centre by up to 1e-16 |t| cx
// / fx, and the error reached 4e-3 px.
TEST(BoxProjectorTest, ProjectionErrorStaysFarBelowTheSlackAtTheLoadersLimits) {
  std::mt19937_64 rng(78);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  double worst = 0.0;
  int checked = 0, cameras = 0;
  for (int camera = 0; camera < 1000; ++camera) {
    // Half of the cameras at the extremes: the longest focal length the
    // loader takes, the other as far from it as allowed.
    const bool extreme = camera % 2 == 0;
    double fx = extreme ? 1e6 : std::pow(10.0, 6.0 * u01(rng));
    double fy = std::clamp(extreme ? fx / geometry::kMaxFocalAspect
                                   : fx * std::pow(geometry::kMaxFocalAspect, 2.0 * u01(rng) - 1.0),
                           1.0, 1e6);
    if (camera % 4 == 2) std::swap(fx, fy);
    const int width = camera % 3 == 0 ? 65535 : 1 + static_cast<int>(4000 * u01(rng));
    const int height = camera % 3 == 1 ? 65535 : 1 + static_cast<int>(4000 * u01(rng));
    // The principal point up to an image size outside, the image reaching at
    // most kMaxImageReach focal lengths from it.
    auto principal = [&](int side, double f) {
      const double c = side * (3.0 * u01(rng) - 1.0);
      const double limit = geometry::kMaxImageReach * f;
      return std::clamp(c, side - limit, limit);
    };
    const double cx = principal(width, fx), cy = principal(height, fy);
    if (std::max(std::abs(cx), std::abs(width - cx)) > geometry::kMaxImageReach * fx ||
        std::max(std::abs(cy), std::abs(height - cy)) > geometry::kMaxImageReach * fy) {
      continue;  // Too short a focal length for so large an image: refused.
    }
    ++cameras;
    Eigen::Matrix3d K;
    K << fx, fx * (2.0 * u01(rng) - 1.0), cx, 0, fy, cy, 0, 0, 1;
    const Eigen::Matrix3d R = Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng))
                                  .normalized()
                                  .matrix();
    const Eigen::Vector3d centre_W(1e6 * (2.0 * u01(rng) - 1.0), 1e6 * (2.0 * u01(rng) - 1.0),
                                   1e6 * (2.0 * u01(rng) - 1.0));
    // The calibration as the loader holds it: K, R and t (t rounded once).
    const Eigen::Vector3d t = -R * centre_W;
    const geometry::BoxProjector projector(K, R, t);
    for (int trial = 0; trial < 100; ++trial) {
      const double depth = std::pow(10.0, -1.3 + 2.0 * u01(rng));
      const Eigen::Vector3d p_C =
          depth * (K.inverse() * Eigen::Vector3d(width * u01(rng), height * u01(rng), 1.0));
      const Eigen::Vector3d p_W = R.transpose() * p_C + centre_W;
      const Eigen::Vector2d uv = projector.ProjectPoint(p_W);
      // K (R p + t) in 113 bits: the camera itself, not K [R | t] rounded.
      __float128 camera_frame[3];
      for (int b = 0; b < 3; ++b) {
        camera_frame[b] = t[b];
        for (int a = 0; a < 3; ++a) camera_frame[b] += static_cast<__float128>(R(b, a)) * p_W[a];
      }
      for (int r = 0; r < 2; ++r) {
        __float128 num = 0, den = 0;
        for (int b = 0; b < 3; ++b) {
          num += static_cast<__float128>(K(r, b)) * camera_frame[b];
          den += static_cast<__float128>(K(2, b)) * camera_frame[b];
        }
        const double exact = static_cast<double>(num / den);
        if (exact < -0.5 || exact > (r == 0 ? width : height) - 0.5) continue;
        ++checked;
        const double error = std::abs(uv[r] - exact);
        worst = std::max(worst, error);
        ASSERT_LT(error, geometry::kFootprintSlackPx / 100)
            << "camera " << camera << " K [" << K.row(0) << "; " << K.row(1) << "], width " << width
            << ", height " << height << ", coordinate " << r << " at " << exact;
      }
    }
  }
  EXPECT_GT(cameras, 800);
  EXPECT_GT(checked, 100000);
  char worst_text[32];
  std::snprintf(worst_text, sizeof(worst_text), "%.3g", worst);
  RecordProperty("worst_error_px", worst_text);
}

TEST(ObstacleRelationTest, SameVerdictAndMonotoneOnSubBoxesAndCertifiesFreeAgrees) {
  int seen_clear = 0, seen_behind = 0, seen_partial = 0, seen_free = 0;
  for (int seed = 0; seed < testing::SoakSeeds(8); ++seed) {
    testing::RandomSceneOptions opt;
    opt.num_cameras = 4;
    opt.num_objects = 3;
    opt.num_obstacles = 2 + seed % 3;
    const testing::RandomScene scene = testing::MakeRandomScene(500 + seed, opt);
    const auto masks = testing::RenderMasks(scene.cameras, scene.objects);
    const auto views = testing::MakeViews(scene.cameras, scene.obstacles);
    std::mt19937_64 rng(seed);
    for (std::size_t c = 0; c < views.size(); ++c) {
      const CameraView& view = views[c];
      if (!view.has_obstacles()) continue;
      silhouette::SilhouetteQuadtree quadtree(view.width(), view.height());
      quadtree.Build(masks[c].View(), 127);
      for (int trial = 0; trial < 400; ++trial) {
        const int level = std::uniform_int_distribution<int>(2, 6)(rng);
        std::uniform_int_distribution<std::uint32_t> coordinate(0, (1u << level) - 1);
        const Cell cell{level, coordinate(rng), coordinate(rng), coordinate(rng)};
        const common::Box3 box = CellBox(scene.bounds, cell);
        const geometry::Footprint fp = view.projector().Project(box.min, box.max);
        const ObstacleRelation relation = RelateToObstacles(view, fp);
        bool geometric_direct = false, geometric_cached = false;
        const Verdict direct =
            Classify(view, &quadtree, fp, ObstacleRelation::kUnknown, &geometric_direct);
        const Verdict cached = Classify(view, &quadtree, fp, relation, &geometric_cached);
        ASSERT_EQ(direct, cached) << "seed " << seed << " camera " << c;
        ASSERT_EQ(geometric_direct, geometric_cached);
        // The free-only test agrees with the verdict, with the relation known or not.
        for (const ObstacleRelation r : {ObstacleRelation::kUnknown, relation}) {
          ASSERT_EQ(CertifiesFree(view, &quadtree, fp, r), direct == Verdict::kFree)
              << "seed " << seed << " camera " << c << " relation " << static_cast<int>(r);
        }
        ASSERT_FALSE(CertifiesFree(view, nullptr, fp, relation));
        seen_free += direct == Verdict::kFree;
        seen_clear += relation == ObstacleRelation::kClear;
        seen_behind += relation == ObstacleRelation::kBehind;
        seen_partial += relation == ObstacleRelation::kPartial;
        if (relation == ObstacleRelation::kPartial) continue;
        // Clear passes to every sub-box; behind makes every sub-box hidden
        // (a sub-box outside the image is hidden too, and vacuously clear).
        for (std::uint32_t i = 0; i < 8; ++i) {
          const common::Box3 sub = CellBox(scene.bounds, cell.Child(i));
          const geometry::Footprint sub_fp = view.projector().Project(sub.min, sub.max);
          if (relation == ObstacleRelation::kClear) {
            EXPECT_EQ(RelateToObstacles(view, sub_fp), ObstacleRelation::kClear)
                << "seed " << seed << " camera " << c << " child " << i;
          } else {
            bool geometric = false;
            EXPECT_EQ(Classify(view, &quadtree, sub_fp, ObstacleRelation::kUnknown, &geometric),
                      Verdict::kHidden)
                << "seed " << seed << " camera " << c << " child " << i;
          }
        }
      }
    }
  }
  // The random scenes exercise every relation.
  EXPECT_GT(seen_clear, 100);
  EXPECT_GT(seen_behind, 10);
  EXPECT_GT(seen_partial, 100);
  EXPECT_GT(seen_free, 100);
}

}  // namespace
}  // namespace hg::octree
