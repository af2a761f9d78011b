// hullguard: command-line tool over the hullguard libraries.
#include <cstdio>
#include <exception>
#include <string>

#include "common/config_error.h"
#include "common/version.h"
#include "hullguard/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"hullguard: conservative multi-camera reconstruction tools"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("hullguard ") + hg::common::Version() + " (" +
                                        hg::common::Commit() + ")");
  int exit_code = hg::tools::kExitOk;
  hg::tools::RegisterCarve(app, &exit_code);
  hg::tools::RegisterDemo(app, &exit_code);
  hg::tools::RegisterSynth(app, &exit_code);
  hg::tools::RegisterBench(app, &exit_code);
  hg::tools::RegisterReplay(app, &exit_code);
  hg::tools::RegisterRecord(app, &exit_code);
  hg::tools::RegisterTrackEval(app, &exit_code);
  hg::tools::RegisterPlace(app, &exit_code);
#ifdef HG_WITH_DDS
  hg::tools::RegisterEcho(app, &exit_code);
#endif
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "hullguard: %s\n", e.what());
    return hg::tools::kExitBadInput;
  } catch (const hg::common::ConfigError& e) {
    std::fprintf(stderr, "hullguard: %s\n", e.what());
    return hg::tools::kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hullguard: error: %s\n", e.what());
    return hg::tools::kExitFailure;
  }
  return exit_code;
}
