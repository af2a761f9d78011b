#pragma once
/// @file
/// A program (hullguardd) running in the background for end-to-end tests:
/// stdout to /dev/null, stderr to a log file the test reads.

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace hg::testing {

/// The whole file, or "" when it cannot be read.
std::string ReadFile(const std::string& path);

/// One background process. Not copyable; the destructor stops it (SIGTERM,
/// then SIGKILL after 5 s) unless it has ended already.
class DaemonProcess {
 public:
  using Clock = std::chrono::steady_clock;

  /// Starts `program` with `args` (after argv[0]); started() says whether it
  /// could be spawned.
  DaemonProcess(const std::string& program, const std::vector<std::string>& args,
                std::string log_path);
  ~DaemonProcess();
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  [[nodiscard]] bool started() const { return started_; }
  [[nodiscard]] pid_t pid() const { return pid_; }
  /// The process has not ended (it is still the one started).
  [[nodiscard]] bool Running();
  /// Waits for the exit; its exit code, -1 when it did not exit normally.
  int Wait();
  /// SIGTERM (as systemctl stop) and waits up to `limit` for the exit.
  /// Returns the exit code (-1 if it did not exit cleanly in time) and sets
  /// *took.
  int Terminate(Clock::duration limit, Clock::duration* took);
  /// The log so far.
  [[nodiscard]] std::string Log() const { return ReadFile(log_path_); }
  /// The CLOCK_REALTIME instant of scene time 0 that hullguardd logs with
  /// simulated cameras ("time 0 is N ns"), waiting up to 20 s for it.
  [[nodiscard]] std::optional<std::int64_t> SceneEpochNs() const;

 private:
  std::string log_path_;
  pid_t pid_ = -1;
  bool started_ = false;
};

}  // namespace hg::testing
