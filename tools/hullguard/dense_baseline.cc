#include "hullguard/dense_baseline.h"

#include <atomic>
#include <cmath>

namespace hg::tools {

DenseCarver::DenseCarver(const common::Box3& bounds, int resolution,
                         const std::vector<geometry::CameraModel>& cameras)
    : bounds_(bounds), n_(resolution) {
  const Eigen::Vector3d step = bounds.Size() / resolution;
  for (const geometry::CameraModel& camera : cameras) {
    const Eigen::Matrix<double, 3, 4> P = camera.ProjectionMatrix();
    AxisTerms t;
    for (int i = 0; i < n_; ++i) {
      const double x = bounds.min.x() + (i + 0.5) * step.x();
      const double y = bounds.min.y() + (i + 0.5) * step.y();
      const double z = bounds.min.z() + (i + 0.5) * step.z();
      t.x.push_back((P.col(0) * x + P.col(3)).cast<float>());
      t.y.push_back((P.col(1) * y).cast<float>());
      t.z.push_back((P.col(2) * z).cast<float>());
    }
    terms_.push_back(std::move(t));
    widths_.push_back(camera.width);
    heights_.push_back(camera.height);
  }
  occupied_.assign(static_cast<std::size_t>(n_) * n_ * n_, 0);
}

std::int64_t DenseCarver::Carve(const std::vector<const common::ImageU8*>& masks,
                                common::WorkerPool& pool) {
  std::atomic<std::int64_t> total{0};
  auto slab = [&](int z, int /*worker*/) {
    std::int64_t count = 0;
    for (int y = 0; y < n_; ++y) {
      std::uint8_t* row = &occupied_[(static_cast<std::size_t>(z) * n_ + y) * n_];
      for (int x = 0; x < n_; ++x) {
        bool occ = true;
        for (std::size_t c = 0; c < terms_.size() && occ; ++c) {
          const Eigen::Vector3f q = terms_[c].x[x] + terms_[c].y[y] + terms_[c].z[z];
          if (q.z() <= 0.0F) continue;
          const int u = static_cast<int>(std::floor(q.x() / q.z() + 0.5F));
          const int v = static_cast<int>(std::floor(q.y() / q.z() + 0.5F));
          if (u < 0 || v < 0 || u >= widths_[c] || v >= heights_[c]) continue;
          occ = masks[c]->At(u, v) > 127;
        }
        row[x] = occ;
        count += occ;
      }
    }
    total.fetch_add(count, std::memory_order_relaxed);
  };
  pool.Run(n_, slab);
  return total.load();
}

bool DenseCarver::Occupied(const Eigen::Vector3d& p_W) const {
  if (!bounds_.Contains(p_W)) return false;
  const Eigen::Vector3d rel = (p_W - bounds_.min).cwiseQuotient(bounds_.Size()) * n_;
  auto index = [&](double v) { return std::min(n_ - 1, std::max(0, static_cast<int>(v))); };
  return occupied_[(static_cast<std::size_t>(index(rel.z())) * n_ + index(rel.y())) * n_ +
                   index(rel.x())] != 0;
}

}  // namespace hg::tools
