#include "common/yaml_file.h"

#include <algorithm>
#include <cstddef>
#include <fstream>
#include <vector>

#include "common/config_error.h"
#include "common/input_file.h"

namespace hg::common {

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
    return documents.empty() ? YAML::Node() : documents.front();
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
