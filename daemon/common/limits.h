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

/// Most 8x8-pixel tiles a camera image may have: the silhouette quadtree adds
/// two 21-bit tile counts before it subtracts one. About 8000 x 8000 pixels.
inline constexpr long long kMaxImageTiles = 1LL << 20;

/// Whether a width x height image stays within kMaxImageTiles.
inline constexpr bool ImageFits(int width, int height) {
  return static_cast<long long>((width + 7) / 8) * ((height + 7) / 8) <= kMaxImageTiles;
}

}  // namespace hg::common
