#include "capture/camera_health.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>

namespace hg::capture {

const char* ToString(CameraFault fault) {
  switch (fault) {
    case CameraFault::kNone:
      return "none";
    case CameraFault::kFrozen:
      return "frozen";
    case CameraFault::kBlack:
      return "black";
    case CameraFault::kSaturated:
      return "saturated";
    case CameraFault::kMoved:
      return "moved";
    case CameraFault::kUnlearned:
      return "unlearned";
    case CameraFault::kBlocked:
      return "blocked";
  }
  return "?";
}

CameraHealthMonitor::CameraHealthMonitor(CameraHealthOptions options) : options_(options) {
  options_.sample_step_px = std::max(1, options_.sample_step_px);
  // ViewRegistration sums up to 255 frames.
  options_.reference_frames = std::clamp(options_.reference_frames, 1, 255);
  options_.shift_check_every = std::max(1, options_.shift_check_every);
}

void CameraHealthMonitor::Reset() {
  reference_count_ = 0;
  reference_edges_.clear();
  std::fill(reference_sum_.begin(), reference_sum_.end(), 0);
  identical_run_ = 0;
  recent_count_ = 0;
  recent_next_ = 0;
  first_frame_.Reset();
  averaged_.Reset();
  active_ = Reference::kFirstFrame;
  shift_while_averaging_ = false;
  frames_since_check_ = 0;
  shift_run_ = 0;
  misalignment_px_ = -1.0;
  shifted_ = false;
  edges_in_place_ = -1.0;
  glance_next_ = 0;
  taught_.Reset();
  taught_pending_ = false;
  taught_agree_ = taught_differ_ = 0;
  moved_since_taught_ = false;
  has_registration_reference_ = false;
  shifted_frames_ = 0;
  moved_ = false;
  edges_kept_ = 1.0;
  fault_ = CameraFault::kNone;
}

void CameraHealthMonitor::Sample(const Frame& frame) {
  const bool rgb = frame.kind == FrameKind::kRgb;
  const int width = rgb ? frame.rgb.width : frame.grey.width;
  const int height = rgb ? frame.rgb.height : frame.grey.height;
  const int step = options_.sample_step_px;
  const int cols = (width + step - 1) / step;
  const int rows = (height + step - 1) / step;
  if (cols != cols_ || rows != rows_) {
    // First frame (or a new size): size the buffers once.
    cols_ = cols;
    rows_ = rows;
    const auto n = static_cast<std::size_t>(cols) * rows;
    current_.assign(n, 0);
    previous_.assign(n, 0);
    reference_sum_.assign(n, 0);
    reference_.assign(n, 0);
    reference_edges_.reserve(n);
    Reset();
  }
  for (int r = 0; r < rows_; ++r) {
    const int v = r * step;
    std::uint8_t* out = current_.data() + static_cast<std::size_t>(r) * cols_;
    if (rgb) {
      for (int c = 0; c < cols_; ++c) {
        const std::uint8_t* p = frame.rgb.Pixel(c * step, v);
        out[c] = static_cast<std::uint8_t>(common::Luma(p));
      }
    } else {
      const std::uint8_t* row = frame.grey.pixels.data() + static_cast<std::size_t>(v) * width;
      for (int c = 0; c < cols_; ++c) out[c] = row[c * step];
    }
  }
}

bool CameraHealthMonitor::EdgeAt(const std::vector<std::uint8_t>& img, int x, int y) const {
  if (x <= 0 || y <= 0 || x >= cols_ - 1 || y >= rows_ - 1) return false;
  const auto at = [&](int cx, int cy) {
    return static_cast<int>(img[static_cast<std::size_t>(cy) * cols_ + cx]);
  };
  const int gx = at(x + 1, y) - at(x - 1, y);
  const int gy = at(x, y + 1) - at(x, y - 1);
  return std::abs(gx) + std::abs(gy) >= 2 * options_.edge_threshold;
}

void CameraHealthMonitor::SetTaughtView(const Frame& taught) {
  taught_.Reset();
  taught_.Accumulate(taught);
  taught_pending_ = taught_.TakeReference() >= ViewRegistration::kFewPatches;
  taught_agree_ = taught_differ_ = 0;
}

CameraFault CameraHealthMonitor::Check(const Frame& frame) {
  if (frame.kind == FrameKind::kMask) return fault_;
  Sample(frame);
  const std::size_t n = current_.size();

  // Frozen: samples bit-identical to one of the last few frames, frame after
  // frame (a driver re-delivering its last buffer, or cycling through its
  // few stale ones). Real sensors have noise: no frame repeats another.
  std::uint64_t hash = 0xcbf29ce484222325ULL;  // FNV-1a, 64 bits.
  for (const std::uint8_t g : current_) hash = (hash ^ g) * 0x100000001b3ULL;
  const bool seen = std::find(recent_.begin(), recent_.begin() + recent_count_, hash) !=
                    recent_.begin() + recent_count_;
  identical_run_ = seen ? identical_run_ + 1 : 0;
  recent_[recent_next_] = hash;
  recent_next_ = (recent_next_ + 1) % static_cast<int>(recent_.size());
  recent_count_ = std::min(recent_count_ + 1, static_cast<int>(recent_.size()));
  std::swap(current_, previous_);  // previous_ now holds this frame.
  const std::vector<std::uint8_t>& img = previous_;

  std::uint64_t sum = 0;
  for (const std::uint8_t g : img) sum += g;
  const double mean = static_cast<double>(sum) / static_cast<double>(n);

  if (!moved_ && mean >= options_.dark_level && mean <= options_.saturated_level) {
    bool registered = false;  // This frame was registered against the taught view.
    if (taught_pending_) {
      // Every frame until settled: the camera's frames wait meanwhile.
      const double taught_px = taught_.Measure(frame);
      registered = true;
      if (taught_px >= 0.0) {
        misalignment_px_ = taught_px;
        const bool differs = taught_px > options_.max_shift_px;
        taught_differ_ = differs ? taught_differ_ + 1 : 0;
        taught_agree_ = differs ? 0 : taught_agree_ + 1;
        if (taught_differ_ >= options_.moved_checks) {
          moved_ = true;
          moved_since_taught_ = true;
          taught_pending_ = false;
        } else if (taught_agree_ >= kTaughtMatches) {
          // Matched: the taught view, the one the calibration holds for (and
          // without people in it), is the reference from now on.
          taught_pending_ = false;
          active_ = Reference::kTaught;
          frames_since_check_ = 0;
        }
      }
    }
    if (!has_registration_reference_) {
      // Registration's first reference is the first frame, so that a move
      // while the reference frames are averaged is found as any other.
      first_frame_.Accumulate(frame);
      first_frame_.TakeReference();
      has_registration_reference_ = true;
      registered = true;
    }
    bool edges_lost = false;
    if (reference_count_ < options_.reference_frames) {
      for (std::size_t i = 0; i < n; ++i) reference_sum_[i] += img[i];
      averaged_.Accumulate(frame);
      if (++reference_count_ == options_.reference_frames) {
        // The average has less noise; it takes over unless the view moved
        // meanwhile (it would be a blend), or the taught view is in use.
        averaged_.TakeReference();
        if (active_ == Reference::kFirstFrame && !shift_while_averaging_ &&
            averaged_.patches() >= first_frame_.patches()) {
          active_ = Reference::kAveraged;
        }
        for (std::size_t i = 0; i < n; ++i) {
          reference_[i] = static_cast<std::uint8_t>(reference_sum_[i] / reference_count_);
        }
        reference_edges_.clear();
        for (int y = 1; y < rows_ - 1; ++y) {
          for (int x = 1; x < cols_ - 1; ++x) {
            if (EdgeAt(reference_, x, y)) {
              reference_edges_.push_back(static_cast<std::uint32_t>(y * cols_ + x));
            }
          }
        }
      }
    } else if (!reference_edges_.empty()) {
      // An edge counts as kept when the frame has an edge at the same sample.
      // The central differences span two grid steps, so a view shifted by
      // less than about a step keeps its edges and one shifted by more loses
      // them; so does a view dimmed, or covered by someone near the lens.
      std::size_t kept = 0;
      for (const std::uint32_t i : reference_edges_) {
        kept += EdgeAt(img, static_cast<int>(i) % cols_, static_cast<int>(i) / cols_) ? 1 : 0;
      }
      edges_kept_ = static_cast<double>(kept) / static_cast<double>(reference_edges_.size());
      // Lost: most of them gone, or clearly fewer than while the view was
      // last found in place (people walking hide some all the time).
      edges_lost = edges_kept_ < options_.min_edges_kept ||
                   (edges_in_place_ >= 0.0 && edges_kept_ < edges_in_place_ - kEdgesDrop);
    }
    // Registration every few frames, and at once when the edges are lost:
    // it tells a move (beyond registration's reach: found nowhere) from a
    // dimmed or covered view (found in place).
    // Between registrations, a glance at a few patches, in turn: a move
    // that they show is registered on its first frame.
    ViewRegistration& reference = active();
    bool due = false;
    if (!registered) {
      due = ++frames_since_check_ >= options_.shift_check_every || edges_lost;
      if (!due && reference.patches() > 0) {
        due = reference.Glance(frame, glance_next_, kGlancePatches, options_.max_shift_px);
        glance_next_ = (glance_next_ + kGlancePatches) % reference.patches();
      }
    }
    if (due) {
      frames_since_check_ = 0;
      const double px = reference.Measure(frame);
      if (px > options_.max_shift_px && reference_count_ < options_.reference_frames) {
        shift_while_averaging_ = true;
      }
      // While the taught view is matched, its misalignment is the one told.
      if (!taught_pending_) misalignment_px_ = px;
      if (px >= 0.0) {
        shifted_ = px > options_.max_shift_px;
        shift_run_ = shifted_ ? shift_run_ + 1 : 0;
        if (shift_run_ >= options_.moved_checks) moved_ = true;
        if (!shifted_ && !reference_edges_.empty() &&
            reference_count_ >= options_.reference_frames) {
          // The edges kept while in place, smoothed over registrations.
          edges_in_place_ =
              edges_in_place_ < 0.0 ? edges_kept_ : 0.9 * edges_in_place_ + 0.1 * edges_kept_;
        }
      } else if (edges_lost) {
        // Too little found to tell, and the edges are gone: a move farther
        // than registration looks, or a view covered; not used either way,
        // until a registration finds it in place.
        shifted_ = true;
      }
      // Otherwise (people in front of most patches) it tells nothing.
    }
  }
  shifted_frames_ = shifted() && !moved_ ? shifted_frames_ + 1 : 0;

  if (moved_) {
    fault_ = CameraFault::kMoved;
  } else if (identical_run_ >= options_.frozen_frames) {
    fault_ = CameraFault::kFrozen;
  } else if (mean < options_.dark_level) {
    fault_ = CameraFault::kBlack;
  } else if (mean > options_.saturated_level) {
    fault_ = CameraFault::kSaturated;
  } else {
    fault_ = CameraFault::kNone;
  }
  return fault_;
}

}  // namespace hg::capture
