#pragma once
/// @file
/// What was built: the project version and the commit of the source tree.

namespace hg::common {

/// "0.1.0".
[[nodiscard]] const char* Version();
/// `git describe --always --dirty` of the source tree at build time ("unknown"
/// outside a git checkout).
[[nodiscard]] const char* Commit();

}  // namespace hg::common
