#include "common/yaml_file.h"

#include <fstream>

#include "common/config_error.h"
#include "common/input_file.h"

namespace hg::common {

YAML::Node ParseYaml(const std::string& text, const std::string& file) {
  try {
    return YAML::Load(text);
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
