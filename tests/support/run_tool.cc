#include "support/run_tool.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace hg::testing {

ProcessResult RunTool(const std::string& binary, const std::string& args) {
  namespace fs = std::filesystem;
  static int counter = 0;
  const fs::path dir = fs::temp_directory_path() / std::string("hg_run_")
                                                       .append(std::to_string(::getpid()))
                                                       .append("_")
                                                       .append(std::to_string(counter++));
  fs::create_directories(dir);
  const fs::path out = dir / "out";
  const fs::path err = dir / "err";
  const std::string cmd = binary + " " + args + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  ProcessResult r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::stringstream so, se;
  so << std::ifstream(out).rdbuf();
  se << std::ifstream(err).rdbuf();
  r.out = so.str();
  r.err = se.str();
  fs::remove_all(dir);
  return r;
}

ProcessResult RunToolInNetns(const std::string& binary, const std::string& args) {
  return RunTool(HG_IN_NETNS_SH, binary + " " + args);
}

}  // namespace hg::testing
