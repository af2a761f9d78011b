#pragma once
/// @file
/// Loading YAML text and files with errors that name the file and the line.

#include <string>

#include <yaml-cpp/yaml.h>

namespace hg::common {

/// The message for a merge key (`<<: *anchor`): yaml-cpp keeps it as a key
/// named "<<" instead of merging, so the anchored keys would go unread.
inline constexpr const char* kMergeKeyText = "merge keys ('<<') are not read: write the keys out";

/// 1-based line of a node, for messages (yaml-cpp marks are 0-based).
[[nodiscard]] inline int YamlLine(const YAML::Node& node) { return node.Mark().line + 1; }

/// Parses YAML text; `file` names it in messages.
/// @throws ConfigError "file:line: malformed YAML: ..." with the parser's line.
[[nodiscard]] YAML::Node ParseYaml(const std::string& text, const std::string& file);

/// Reads and parses a YAML file.
/// @throws ConfigError when the file cannot be read or is malformed.
[[nodiscard]] YAML::Node LoadYamlFile(const std::string& path);

/// Writes what `out` emitted to `path` (replacing the file).
/// @throws ConfigError when the emitter failed or the file cannot be written.
void WriteYamlFile(const std::string& path, const YAML::Emitter& out);

}  // namespace hg::common
