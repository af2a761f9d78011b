#pragma once
/// @file
/// The configuration reference as data: what config.cc's field tables say about
/// each key, for ConfigReferenceMarkdown() and tests.

#include <string>
#include <vector>

namespace hg::app {

/// One key of the reference table.
struct DocRow {
  std::string key;
  std::string type;
  std::string default_value;  ///< "required" for keys without a default.
  std::string allowed;        ///< Range or allowed values; empty when any value of the type.
  std::string meaning;
};

/// One table of the reference: a section of the file, or a kind of camera source.
struct DocSection {
  std::string title;   ///< Heading, e.g. "octree".
  std::string prefix;  ///< Key path of the rows, e.g. "cameras[].source".
  std::string intro;   ///< One or two sentences above the table.
  std::vector<DocRow> rows;
};

/// Every section with every key, in the order of the reference (defined with the
/// field tables in config.cc).
[[nodiscard]] std::vector<DocSection> ConfigDocSections();

/// A small complete config shown in the reference; valid with config/ as its folder.
[[nodiscard]] std::string ConfigExampleYaml();

}  // namespace hg::app
