#include "capture/view_registration.h"

#include <algorithm>
#include <cmath>
#include <complex>

#include <Eigen/Dense>

#include "common/image.h"

namespace hg::capture {
namespace {

// Grid of cells over the view, one patch (the best corner) per cell.
constexpr int kCellCols = 8;
constexpr int kCellRows = 6;
static_assert(kCellCols * kCellRows <= ViewRegistration::kMaxPatches);
// Candidate patches are tried every this many pixels.
constexpr int kCandidateStep = 4;
// Smaller eigenvalue of the structure tensor (grey levels per pixel, squared,
// per pixel) a patch needs: texture in two directions, so that it can be found
// again to a fraction of a pixel (an edge alone slides along itself).
constexpr double kMinCornerness = 4.0;

// Normalised cross-correlation of a zero-mean, unit-norm `ref` of side `side`
// with the window of `region` (side `region_side`) whose top left is (x, y).
double Correlation(const float* ref, int side, const float* region, int region_side, int x, int y) {
  double rc = 0, c = 0, cc = 0;
  for (int v = 0; v < side; ++v) {
    const float* row = region + static_cast<std::ptrdiff_t>(y + v) * region_side + x;
    const float* r = ref + static_cast<std::ptrdiff_t>(v) * side;
    for (int u = 0; u < side; ++u) {
      rc += r[u] * row[u];
      c += row[u];
      cc += row[u] * row[u];
    }
  }
  const double n = static_cast<double>(side) * side;
  const double variance = cc - c * c / n;
  // A flat window (under half a grey level of spread) matches nothing.
  if (variance < 0.25 * n) return 0.0;
  return rc / std::sqrt(variance);
}

// Makes `values` zero-mean and of unit norm; false when they are flat.
template <std::size_t N>
bool Normalise(std::array<float, N>* values) {
  double mean = 0;
  for (const float v : *values) mean += v;
  mean /= static_cast<double>(N);
  double norm = 0;
  for (float& v : *values) {
    v = static_cast<float>(v - mean);
    norm += static_cast<double>(v) * v;
  }
  if (norm < 0.25 * static_cast<double>(N)) return false;
  const double scale = 1.0 / std::sqrt(norm);
  for (float& v : *values) v = static_cast<float>(v * scale);
  return true;
}

}  // namespace

void ViewRegistration::Size(int width, int height) {
  const auto pixels = static_cast<std::size_t>(width) * height;
  if (width == width_ && height == height_ && sum_.size() == pixels) return;
  if (width != width_ || height != height_) {
    width_ = width;
    height_ = height;
    Reset();
  }
  sum_.assign(pixels, 0);  // Released again by TakeReference().
  frames_ = 0;
  patches_.reserve(kMaxPatches);
}

void ViewRegistration::Reset() {
  std::fill(sum_.begin(), sum_.end(), 0);
  frames_ = 0;
  patches_.clear();
  matched_ = inliers_ = 0;
}

void ViewRegistration::Accumulate(const Frame& frame) {
  const bool rgb = frame.kind == FrameKind::kRgb;
  Size(rgb ? frame.rgb.width : frame.grey.width, rgb ? frame.rgb.height : frame.grey.height);
  if (frames_ >= 255) return;  // The sums are 16 bits.
  std::uint16_t* out = sum_.data();
  if (rgb) {
    const std::uint8_t* p = frame.rgb.pixels.data();
    for (std::size_t i = 0; i < sum_.size(); ++i, p += 3) {
      out[i] = static_cast<std::uint16_t>(out[i] + common::Luma(p));
    }
  } else {
    const std::uint8_t* p = frame.grey.pixels.data();
    for (std::size_t i = 0; i < sum_.size(); ++i) {
      out[i] = static_cast<std::uint16_t>(out[i] + p[i]);
    }
  }
  ++frames_;
}

int ViewRegistration::TakeReference() {
  patches_.clear();
  if (frames_ == 0) return 0;
  const double scale = 1.0 / frames_;
  const auto ref = [&](int x, int y) {
    return sum_[static_cast<std::size_t>(y) * width_ + x] * scale;
  };
  // Patch corners (x0, y0) that leave room to search around them.
  const int x_lo = kMargin, x_hi = width_ - kPatchPx - kMargin;
  const int y_lo = kMargin, y_hi = height_ - kPatchPx - kMargin;
  if (x_hi < x_lo || y_hi < y_lo) return 0;
  for (int row = 0; row < kCellRows; ++row) {
    for (int col = 0; col < kCellCols; ++col) {
      const int cx0 = x_lo + (x_hi - x_lo + 1) * col / kCellCols;
      const int cx1 = x_lo + (x_hi - x_lo + 1) * (col + 1) / kCellCols;
      const int cy0 = y_lo + (y_hi - y_lo + 1) * row / kCellRows;
      const int cy1 = y_lo + (y_hi - y_lo + 1) * (row + 1) / kCellRows;
      // The few best corners of the cell, best first.
      std::array<Candidate, kCandidatesPerCell> best{};
      for (int y0 = cy0; y0 < cy1; y0 += kCandidateStep) {
        for (int x0 = cx0; x0 < cx1; x0 += kCandidateStep) {
          // Structure tensor over the patch, every other pixel.
          double xx = 0, xy = 0, yy = 0;
          for (int v = y0; v < y0 + kPatchPx; v += 2) {
            for (int u = x0; u < x0 + kPatchPx; u += 2) {
              const double gx = 0.5 * (ref(u + 1, v) - ref(u - 1, v));
              const double gy = 0.5 * (ref(u, v + 1) - ref(u, v - 1));
              xx += gx * gx;
              xy += gx * gy;
              yy += gy * gy;
            }
          }
          constexpr double kSamples = (kPatchPx / 2) * (kPatchPx / 2);
          xx /= kSamples;
          xy /= kSamples;
          yy /= kSamples;
          const double smaller =
              0.5 * (xx + yy) - std::sqrt(0.25 * (xx - yy) * (xx - yy) + xy * xy);
          if (smaller > kMinCornerness && smaller > best.back().score) {
            best.back() = {smaller, x0, y0};
            std::sort(best.begin(), best.end(),
                      [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
          }
        }
      }
      for (const Candidate& candidate : best) {
        if (candidate.x0 < 0) break;
        Patch& patch = scratch_patch_;
        patch.x0 = candidate.x0;
        patch.y0 = candidate.y0;
        for (int v = 0; v < kPatchPx; ++v) {
          for (int u = 0; u < kPatchPx; ++u) {
            patch.full[static_cast<std::size_t>(v) * kPatchPx + u] =
                static_cast<float>(ref(patch.x0 + u, patch.y0 + v));
          }
        }
        for (int v = 0; v < kHalfPatch; ++v) {
          for (int u = 0; u < kHalfPatch; ++u) {
            const auto at = [&](int du, int dv) {
              return patch.full[static_cast<std::size_t>(2 * v + dv) * kPatchPx + 2 * u + du];
            };
            patch.half[static_cast<std::size_t>(v) * kHalfPatch + u] =
                0.25F * (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1));
          }
        }
        if (!Normalise(&patch.full) || !Normalise(&patch.half)) continue;
        patches_.push_back(patch);
        break;
      }
    }
  }
  // The sums are not needed any more: their memory (2 bytes a pixel) goes.
  std::vector<std::uint16_t>().swap(sum_);
  frames_ = 0;
  return patches();
}

void ViewRegistration::ReadRegion(const Frame& frame, int x0, int y0) {
  for (int v = 0; v < kRegionPx; ++v) {
    float* row = region_.data() + static_cast<std::ptrdiff_t>(v) * kRegionPx;
    if (frame.kind == FrameKind::kRgb) {
      const std::uint8_t* p = frame.rgb.Pixel(x0, y0 + v);
      for (int u = 0; u < kRegionPx; ++u, p += 3) {
        row[u] = static_cast<float>(common::Luma(p));
      }
    } else {
      const std::uint8_t* p =
          frame.grey.pixels.data() + static_cast<std::size_t>(y0 + v) * frame.grey.width + x0;
      for (int u = 0; u < kRegionPx; ++u) row[u] = static_cast<float>(p[u]);
    }
  }
  for (int v = 0; v < kHalfRegion; ++v) {
    for (int u = 0; u < kHalfRegion; ++u) {
      const auto at = [&](int du, int dv) {
        return region_[static_cast<std::size_t>(2 * v + dv) * kRegionPx + 2 * u + du];
      };
      region_half_[static_cast<std::size_t>(v) * kHalfRegion + u] =
          0.25F * (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1));
    }
  }
}

double ViewRegistration::Measure(const Frame& frame) {
  matched_ = inliers_ = 0;
  if (patches_.empty() || !FitsFrame(frame)) return -1.0;
  for (std::size_t i = 0; i < patches_.size(); ++i) matched_ += Find(frame, i) ? 1 : 0;
  return FitAndMeasure();
}

bool ViewRegistration::Glance(const Frame& frame, int first, int count, double beyond_px) {
  if (patches_.empty() || !FitsFrame(frame)) return false;
  int moved = 0;
  const int n = patches();
  for (int k = 0; k < std::min(count, n); ++k) {
    const auto i = static_cast<std::size_t>((first + k) % n);
    // Patches of a repetitive texture count too: one settled a period off
    // costs a registration, which tells.
    if (Find(frame, i) && std::hypot(found_[i].dx, found_[i].dy) > beyond_px) ++moved;
  }
  return moved >= kGlanceAgree;
}

bool ViewRegistration::FitsFrame(const Frame& frame) const {
  const bool rgb = frame.kind == FrameKind::kRgb;
  return (rgb ? frame.rgb.width : frame.grey.width) == width_ &&
         (rgb ? frame.rgb.height : frame.grey.height) == height_;
}

bool ViewRegistration::Find(const Frame& frame, std::size_t i) {
  const Patch& patch = patches_[i];
  Found& found = found_[i];
  found = {};
  found.x = patch.x0 + 0.5 * kPatchPx - 0.5 * width_;
  found.y = patch.y0 + 0.5 * kPatchPx - 0.5 * height_;
  ReadRegion(frame, patch.x0 - kMargin, patch.y0 - kMargin);
  // Coarse: every shift of up to kSearchPx, in steps of two pixels.
  constexpr int kHalfSearch = kSearchPx / 2;
  constexpr int kHalfMargin = kMargin / 2;
  constexpr int kCoarseSide = 2 * kHalfSearch + 1;
  double best = -2.0;
  int dx = 0, dy = 0;
  for (int oy = -kHalfSearch; oy <= kHalfSearch; ++oy) {
    for (int ox = -kHalfSearch; ox <= kHalfSearch; ++ox) {
      const double s = Correlation(patch.half.data(), kHalfPatch, region_half_.data(), kHalfRegion,
                                   kHalfMargin + ox, kHalfMargin + oy);
      coarse_[static_cast<std::size_t>(oy + kHalfSearch) * kCoarseSide + ox + kHalfSearch] =
          static_cast<float>(s);
      if (s > best) {
        best = s;
        dx = 2 * ox;
        dy = 2 * oy;
      }
    }
  }
  // A repetitive texture (a rack, a grating) matches nearly as well a
  // period away, where the search could settle and read a move that did
  // not happen: a second peak nearly as high leaves the patch out.
  bool ambiguous = false;
  for (int y = 0; y < kCoarseSide && !ambiguous; ++y) {
    for (int x = 0; x < kCoarseSide && !ambiguous; ++x) {
      if (std::abs(2 * (x - kHalfSearch) - dx) <= 2 && std::abs(2 * (y - kHalfSearch) - dy) <= 2) {
        continue;  // The best peak itself.
      }
      const float c = coarse_[static_cast<std::size_t>(y) * kCoarseSide + x];
      if (c < best - kAmbiguityMargin) continue;
      bool peak = true;  // A local maximum (the border counts as lower).
      for (int k = 0; k < 9 && peak; ++k) {
        const int nx = x + k % 3 - 1, ny = y + k / 3 - 1;
        if (k == 4 || nx < 0 || ny < 0 || nx >= kCoarseSide || ny >= kCoarseSide) continue;
        peak = c >= coarse_[static_cast<std::size_t>(ny) * kCoarseSide + nx];
      }
      ambiguous = peak;
    }
  }
  found.ambiguous = ambiguous;
  // Fine: climb to the best whole-pixel shift at full resolution.
  const auto score = [&](int sx, int sy) {
    return Correlation(patch.full.data(), kPatchPx, region_.data(), kRegionPx, kMargin + sx,
                       kMargin + sy);
  };
  std::array<double, 9> around{};
  bool peak = false;
  for (int step = 0; step < 4 && !peak; ++step) {
    int best_k = 4;
    for (int k = 0; k < 9; ++k) {
      around[k] = score(dx + k % 3 - 1, dy + k / 3 - 1);
      if (around[k] > around[best_k]) best_k = k;
    }
    if (best_k == 4) {
      peak = true;
    } else {
      dx += best_k % 3 - 1;
      dy += best_k / 3 - 1;
      if (std::abs(dx) > kSearchPx || std::abs(dy) > kSearchPx) break;
    }
  }
  if (!peak || around[4] < kMinCorrelation) return false;
  // Sub-pixel: a parabola through the scores on either side, each way.
  const double curve_x = around[3] - 2.0 * around[4] + around[5];
  const double curve_y = around[1] - 2.0 * around[4] + around[7];
  if (curve_x >= 0.0 || curve_y >= 0.0) return false;
  found.dx = dx + std::clamp(0.5 * (around[3] - around[5]) / curve_x, -0.5, 0.5);
  found.dy = dy + std::clamp(0.5 * (around[1] - around[7]) / curve_y, -0.5, 0.5);
  found.ok = true;
  return true;
}

double ViewRegistration::FitAndMeasure() {
  const int n = patches();
  const int needed = std::max(kFewPatches, n / 4);
  if (matched_ < needed) return -1.0;
  // The similarity, as displacement d = [s -r; r s] p + t of the place p,
  // that most patches agree with (a patch that matches nearly as well
  // elsewhere counts half): every pair of patches found gives one. Patches of
  // a repetitive texture that settled a period off, or of things moved in
  // the cell, disagree with it and with each other.
  Eigen::Vector4d params(0.0, 0.0, 0.0, 0.0);
  const auto displacement = [&](const Found& f) {
    return Eigen::Vector2d(params[0] * f.x - params[1] * f.y + params[2],
                           params[1] * f.x + params[0] * f.y + params[3]);
  };
  const auto residual = [&](const Found& f) {
    return (displacement(f) - Eigen::Vector2d(f.dx, f.dy)).norm();
  };
  // A shift (one patch) is preferred to a roll or zoom (two) unless that is
  // clearly better: a small zoom can pass near two clusters of patches (the
  // view, and a repetitive texture a period off) at once.
  double most_shift = -1.0, most = -1.0;
  Eigen::Vector4d best_shift = params, best = params;
  for (int i = 0; i < n; ++i) {
    if (!found_[i].ok) continue;
    for (int j = i; j < n; ++j) {
      if (!found_[j].ok) continue;
      const Found& a = found_[i];
      const Found& b = found_[j];
      // q = z p + t in complex numbers, q = p + d; one patch: a shift only.
      const std::complex<double> pa(a.x, a.y), pb(b.x, b.y);
      const std::complex<double> qa = pa + std::complex<double>(a.dx, a.dy);
      const std::complex<double> qb = pb + std::complex<double>(b.dx, b.dy);
      const std::complex<double> z = i == j ? 1.0 : (qa - qb) / (pa - pb);
      const std::complex<double> t = qa - z * pa;
      const double s = z.real() - 1.0, r = z.imag(), tx = t.real(), ty = t.imag();
      double support = 0.0;
      for (int k = 0; k < n; ++k) {
        const Found& f = found_[k];
        const double ex = s * f.x - r * f.y + tx - f.dx;
        const double ey = r * f.x + s * f.y + ty - f.dy;
        if (f.ok && ex * ex + ey * ey <= kAgreePx * kAgreePx) support += f.ambiguous ? 0.5 : 1.0;
      }
      params = {s, r, tx, ty};
      if (i == j && support > most_shift) {
        most_shift = support;
        best_shift = params;
      } else if (i != j && support > most) {
        most = support;
        best = params;
      }
    }
  }
  params = most > kPreferShift * most_shift ? best : best_shift;
  // Refined by least squares over the patches that agree with it (a shift
  // stays a shift).
  const bool shift_only = most <= kPreferShift * most_shift;
  for (int round = 0; round < 2; ++round) {
    Eigen::Matrix4d normal = Eigen::Matrix4d::Zero();
    Eigen::Vector4d rhs = Eigen::Vector4d::Zero();
    int kept = 0;
    for (int i = 0; i < n; ++i) {
      const Found& f = found_[i];
      if (!f.ok || residual(f) > kAgreePx) continue;
      // Rows of the two equations, in units of a thousand pixels for p.
      const Eigen::Vector4d row_x(f.x * 1e-3, -f.y * 1e-3, 1.0, 0.0);
      const Eigen::Vector4d row_y(f.y * 1e-3, f.x * 1e-3, 0.0, 1.0);
      normal += row_x * row_x.transpose() + row_y * row_y.transpose();
      rhs += row_x * f.dx + row_y * f.dy;
      ++kept;
    }
    if (kept < 3) break;  // Too few to tell a roll or zoom apart: as it is.
    if (shift_only) {
      params[2] = rhs[2] / kept;
      params[3] = rhs[3] / kept;
    } else {
      Eigen::Vector4d solved = normal.ldlt().solve(rhs);
      solved[0] *= 1e-3;
      solved[1] *= 1e-3;
      params = solved;
    }
  }
  inliers_ = 0;
  for (int i = 0; i < n; ++i) inliers_ += found_[i].ok && residual(found_[i]) <= kAgreePx ? 1 : 0;
  if (inliers_ < needed) return -1.0;
  // The largest displacement at any patch's place: the patches spread over
  // the view, so this is about the largest anywhere in it.
  double largest = 0.0;
  for (int i = 0; i < n; ++i) largest = std::max(largest, displacement(found_[i]).norm());
  return largest;
}

}  // namespace hg::capture
