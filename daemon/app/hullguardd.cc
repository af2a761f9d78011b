/// @file
/// hullguardd: flags -> load config -> build pipeline -> run.

#include <unistd.h>

#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <new>
#include <string>
#include <string_view>

#include <yaml-cpp/yaml.h>
#include <CLI/CLI.hpp>

#include "app/config.h"
#include "app/run.h"
#include "common/cli_checks.h"
#include "common/config_error.h"
#include "common/version.h"

namespace {

/// Exit codes: 0 ok, 1 cannot run, 2 bad configuration or command line.
constexpr int kExitCannotRun = 1;
constexpr int kExitBadConfig = 2;

/// "" when CYCLONEDDS_URI is unset or every file:// it names is a readable
/// file; else what is wrong. (Inline XML and other URIs are Cyclone's to
/// read.)
std::string CycloneddsUriProblem() {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr) return "";
  std::string_view rest(uri);
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    std::string_view item = rest.substr(0, comma);
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
    while (!item.empty() && std::isspace(static_cast<unsigned char>(item.front()))) {
      item.remove_prefix(1);
    }
    while (!item.empty() && std::isspace(static_cast<unsigned char>(item.back()))) {
      item.remove_suffix(1);
    }
    constexpr std::string_view kFile = "file://";
    if (item.substr(0, kFile.size()) != kFile) continue;
    const std::string path(item.substr(kFile.size()));
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec) || access(path.c_str(), R_OK) != 0) {
      return "CYCLONEDDS_URI names " + std::string(item) + ", which is not a readable file";
    }
  }
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"hullguardd: conservative visual-hull safety monitor daemon"};
  std::string config_path;
  std::string check_path;
  bool print_docs = false;
  bool learn_background = false;
  double duration_s = 0.0;
  // No CLI::ExistingFile check: the loader reports a missing file as every
  // other bad config, "file: cannot open", with exit code 2.
  auto* config_opt = app.add_option("--config", config_path, "Run with this config file");
  auto* check_opt = app.add_option("--check-config", check_path,
                                   "Validate a config file, print a summary and exit");
  auto* docs_opt = app.add_flag("--print-config-docs", print_docs,
                                "Print the configuration reference (docs/configuration.md)");
  auto* learn_opt = app.add_flag(
      "--learn-background", learn_background,
      "With --config: learn every camera's background afresh (the cell must be empty), keep it "
      "in background.keep_dir, and exit (0: every camera kept one); publishes nothing");
  auto* duration_opt = app.add_option("--duration", duration_s,
                                      "With --config: stop after running this many seconds, "
                                      "start-up not counted (0: run until "
                                      "SIGTERM or SIGINT); with --learn-background: give up "
                                      "after this many seconds (default 60)")
                           ->check(hg::cli::kNonNegative)
                           ->check(hg::cli::kFinite);
  app.set_version_flag("--version", std::string("hullguardd ") + hg::common::Version() + " (" +
                                        hg::common::Commit() + ")");
  config_opt->excludes(check_opt)->excludes(docs_opt);
  learn_opt->needs(config_opt);
  check_opt->excludes(docs_opt);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help.
    // A bad command line, like a bad config, cannot be fixed by a restart
    // (the unit's RestartPreventExitStatus=2); CLI11's own codes are > 100.
    std::cerr << "hullguardd: " << e.what() << " (--help lists the options)\n";
    return kExitBadConfig;
  }
  if (config_path.empty() && check_path.empty() && !print_docs) {
    std::cerr << "hullguardd: give --config FILE, --check-config FILE or --print-config-docs\n";
    return kExitBadConfig;
  }

  if (print_docs) {
    std::cout << hg::app::ConfigReferenceMarkdown();
    return 0;
  }
  if (!config_path.empty()) hg::app::InstallStopSignals();
  const std::string& path = check_path.empty() ? config_path : check_path;
  hg::app::Config config;
  try {
    config = hg::app::LoadConfig(path);
  } catch (const hg::common::ConfigError& e) {
    std::cerr << e.what() << '\n';
    return kExitBadConfig;
  } catch (const std::exception& e) {
    // The loader reports bad input as ConfigError; whatever else escapes it
    // (a yaml-cpp conversion) is still about this file.
    std::cerr << path << ": " << e.what() << '\n';
    return kExitBadConfig;
  }
  if (config.dds.enabled) {
    // A Cyclone DDS config file that is not there makes the daemon's DDS
    // participant fail at start: exit 1, which systemd restarts until its
    // start limit. It is the deployment's config, so it is named here, as a
    // bad config, before anything is opened.
    if (const std::string problem = CycloneddsUriProblem(); !problem.empty()) {
      std::cerr << "hullguardd: " << problem << '\n';
      return kExitBadConfig;
    }
  }
  for (const std::string& notice : config.notices) std::cerr << notice << '\n';
  try {
    for (const std::string& notice : hg::app::SimSpeedNotices(config)) {
      std::cerr << notice << '\n';
    }
  } catch (const std::exception& e) {
    // The scenes loaded once already (LoadConfig); a notice is no reason to stop.
    std::cerr << path << ": speed of the simulated people not checked: " << e.what() << '\n';
  }
  if (!check_path.empty()) {
    for (const std::string& notice : hg::app::BlockedCameraNotices(config)) {
      std::cerr << notice << '\n';
    }
    if (duration_opt->count() > 0) {
      std::cerr << "hullguardd: --duration has no effect with --check-config\n";
    }
    std::cout << "config OK: " << hg::app::Summary(config) << '\n';
    return 0;
  }
  if (hg::app::StopRequested()) {
    std::cerr << "hullguardd: stopped during start-up\n";
    return 0;
  }
  try {
    if (learn_background) {
      return hg::app::LearnBackground(config, duration_s > 0.0 ? duration_s : 60.0);
    }
    return hg::app::RunPipeline(config, duration_s);
  } catch (const hg::common::ConfigError& e) {
    std::cerr << e.what() << '\n';
    return kExitBadConfig;
  } catch (const YAML::Exception& e) {
    // A file the config names (scene, recording) that yaml-cpp could not
    // convert: bad input, which a restart cannot fix.
    std::cerr << path << ": " << e.what() << '\n';
    return kExitBadConfig;
  } catch (const std::bad_alloc&) {
    // The memory the config asks for is allocated at start-up; say which
    // settings size it.
    std::cerr << "hullguardd: out of memory while starting: the config asks for more than this "
                 "machine gives (octree.max_nodes, tracking.particles and tracking.max_tracks, "
                 "blackbox.seconds, replay sources with preload size the largest parts)\n";
    return kExitCannotRun;
  } catch (const std::exception& e) {
    std::cerr << "hullguardd: " << e.what() << '\n';
    return kExitCannotRun;
  }
}
