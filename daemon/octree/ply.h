#pragma once
/// @file
/// Export of octree leaves as PLY.

#include <string>

#include "octree/octree.h"

namespace hg::octree {

/// Writes the occupied and occluded leaves as an ASCII PLY mesh: every leaf is a
/// box (8 vertices, 6 quadrilateral faces), coloured per vertex: occupied red
/// (200, 40, 40), occluded grey (128, 128, 128). Coordinates in metres, world frame.
/// @throws common::ConfigError when the file cannot be written.
void WriteOccupiedPly(const Octree& tree, const std::string& path);

}  // namespace hg::octree
