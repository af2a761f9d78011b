#include "common/yaml_file.h"

#include <algorithm>
#include <cstddef>
#include <fstream>
#include <string>
#include <string_view>
#include <unordered_set>
#include <vector>

#include "common/config_error.h"
#include "common/input_file.h"

namespace hg::common {

namespace {

/// A tag (`!!str 7`, `!custom x`) is no instruction the readers follow:
/// `depth: !!str 7` was read as the number 7. Refused, naming its line.
/// Each node once (an alias is the node it names), without recursion (a
/// deeply nested file must not end the stack).
void RefuseTags(const YAML::Node& root, const std::string& file) {
  std::vector<YAML::Node> open = {root};
  std::unordered_set<std::size_t> seen;
  while (!open.empty()) {
    const YAML::Node node = open.back();
    open.pop_back();
    if (!node.IsDefined()) continue;
    // A node by where it starts and its type: a block map starts where its
    // first key does.
    if (const int pos = node.Mark().pos;
        pos >= 0 &&
        !seen.insert(static_cast<std::size_t>(pos) * 8 + static_cast<std::size_t>(node.Type()))
             .second) {
      continue;
    }
    std::string tag = node.Tag();
    if (!tag.empty() && tag != "?" && tag != "!") {
      if (constexpr std::string_view kCore = "tag:yaml.org,2002:"; tag.starts_with(kCore)) {
        tag.replace(0, kCore.size(), "!!");  // As it was written.
      }
      throw ConfigError::At(file, node.Mark().line + 1,
                            "a YAML tag ('" + tag + "'): tags are not read, write the plain value");
    }
    if (node.IsSequence()) {
      for (const YAML::Node& item : node) open.push_back(item);
    } else if (node.IsMap()) {
      for (const auto& entry : node) {
        open.push_back(entry.first);
        open.push_back(entry.second);
      }
    }
  }
}

}  // namespace

YAML::Node ParseYaml(const std::string& text, const std::string& file) {
  // yaml-cpp takes a NUL byte into keys and values, and messages naming them
  // were cut or garbled by it: a file holding one is no YAML text.
  if (const std::size_t nul = text.find('\0'); nul != std::string::npos) {
    const auto line =
        std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(nul), '\n');
    throw ConfigError::At(file, static_cast<int>(line) + 1,
                          "a NUL byte: not a YAML text file (binary, or saved as UTF-16?)");
  }
  try {
    // Every document: a second one (after `---`) would otherwise be dropped
    // unread, settings and all.
    std::vector<YAML::Node> documents = YAML::LoadAll(text);
    if (documents.size() > 1) {
      throw ConfigError::At(file, documents[1].Mark().line + 1,
                            "a second YAML document ('---'): a file holds one");
    }
    if (documents.empty()) return YAML::Node();
    RefuseTags(documents.front(), file);
    return documents.front();
  } catch (const YAML::ParserException& e) {
    throw ConfigError::At(file, e.mark.line + 1, "malformed YAML: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw ConfigError::At(file, e.mark.line + 1, "cannot read YAML: " + e.msg);
  }
}

YAML::Node LoadYamlFile(const std::string& path) {
  return ParseYaml(ReadInputFile(path, ""), path);
}

void WriteYamlFile(const std::string& path, const YAML::Emitter& out) {
  if (!out.good()) throw ConfigError::At(path, 0, "cannot write: " + out.GetLastError());
  std::ofstream file(path, std::ios::out | std::ios::trunc);
  file << out.c_str() << '\n';
  file.close();
  if (!file) throw ConfigError::At(path, 0, "cannot write");
}

}  // namespace hg::common
