#pragma once
// The benchmark workload of docs/performance.md: the demo cell (4 m cube),
// Full HD cameras, three walking people, a table and a rack; masks rendered
// exactly once per frame and cached for all benchmarks of the run.

#include <memory>
#include <vector>

#include "common/image.h"
#include "octree/camera_view.h"
#include "scene/demo_cell.h"

namespace hg::bench {

struct BenchScene {
  scene::DemoCell cell;
  std::vector<std::vector<common::ImageU8>> frames;  // frames[f][camera]
};

/// Cached scene with `num_cameras` Full HD cameras and `num_frames` frames at 30 Hz.
const BenchScene& GetBenchScene(int num_cameras, int num_frames);

/// Camera views of the scene (obstacles included).
std::vector<octree::CameraView> BenchViews(const BenchScene& scene);

}  // namespace hg::bench
