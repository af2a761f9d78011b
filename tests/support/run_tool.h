#pragma once
/// @file
/// Runs a command-line tool of the project and captures its exit code and output.

#include <string>

namespace hg::testing {

struct ProcessResult {
  int code = -1;
  std::string out;
  std::string err;
};

/// Runs `binary args` through the shell, stdout and stderr captured through
/// temporary files that are removed again.
ProcessResult RunTool(const std::string& binary, const std::string& args);

/// Exit code of RunToolInNetns() when no network namespace can be made.
inline constexpr int kNoNetns = 77;

/// RunTool() inside a private network namespace that holds only loopback,
/// with Cyclone DDS on lo without multicast (tests/publish/in_netns.sh): for
/// a tool that publishes over DDS, such as hullguardd, so that it sends
/// nothing off this machine and sees no other test's publishers. Exit code
/// kNoNetns when no namespace can be made (the caller skips).
ProcessResult RunToolInNetns(const std::string& binary, const std::string& args);

}  // namespace hg::testing
