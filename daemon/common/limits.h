#pragma once
/// @file
/// Limits shared by the loaders and the engine, so that input beyond them is
/// refused where it is read, with its file and line, not deep in the engine.

namespace hg::common {

/// Cameras one octree fuses: each node keeps two verdict bits per camera in a
/// 32-bit word.
inline constexpr int kMaxCameras = 16;

/// Largest coordinate (m) of a cell's bounds or a camera's position: beyond
/// it, volumes and cell counts lose their meaning (and overflow).
inline constexpr double kMaxCoordinateM = 1e6;

}  // namespace hg::common
