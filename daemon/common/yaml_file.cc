#include "common/yaml_file.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/config_error.h"

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
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw ConfigError::At(path, 0, "is a folder, not a file");
  std::ifstream in(path);
  if (!in) throw ConfigError::At(path, 0, "cannot open");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw ConfigError::At(path, 0, "read error");
  return ParseYaml(text.str(), path);
}

void WriteYamlFile(const std::string& path, const YAML::Emitter& out) {
  if (!out.good()) throw ConfigError::At(path, 0, "cannot write: " + out.GetLastError());
  std::ofstream file(path, std::ios::out | std::ios::trunc);
  file << out.c_str() << '\n';
  file.close();
  if (!file) throw ConfigError::At(path, 0, "cannot write");
}

}  // namespace hg::common
