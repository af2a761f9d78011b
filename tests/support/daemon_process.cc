#include "support/daemon_process.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <thread>
#include <utility>

extern char** environ;

namespace hg::testing {

using namespace std::chrono_literals;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

DaemonProcess::DaemonProcess(const std::string& program, const std::vector<std::string>& args,
                             std::string log_path)
    : log_path_(std::move(log_path)) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 2, log_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  std::vector<std::string> all = {program};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  started_ = posix_spawn(&pid_, program.c_str(), &actions, nullptr, argv.data(), environ) == 0;
  if (!started_) pid_ = -1;
  posix_spawn_file_actions_destroy(&actions);
}

DaemonProcess::~DaemonProcess() {
  if (pid_ <= 0) return;
  Clock::duration took{};
  if (Terminate(5s, &took) == -1 && pid_ > 0) {
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
}

bool DaemonProcess::Running() {
  int status = 0;
  return pid_ > 0 && waitpid(pid_, &status, WNOHANG) == 0;
}

int DaemonProcess::Wait() {
  int status = 0;
  if (pid_ <= 0 || waitpid(pid_, &status, 0) != pid_) return -1;
  pid_ = -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

int DaemonProcess::Terminate(Clock::duration limit, Clock::duration* took) {
  const Clock::time_point start = Clock::now();
  if (pid_ <= 0) {
    *took = Clock::duration::zero();
    return -1;
  }
  kill(pid_, SIGTERM);
  int status = 0;
  while (Clock::now() - start < limit) {
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      *took = Clock::now() - start;
      pid_ = -1;
      return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }
    std::this_thread::sleep_for(10ms);  // Polls the exit; there is no event to wait on.
  }
  *took = Clock::now() - start;
  return -1;
}

std::optional<std::int64_t> DaemonProcess::SceneEpochNs() const {
  const std::regex line("time 0 is ([0-9]+) ns");
  for (const auto give_up = Clock::now() + 20s; Clock::now() < give_up;
       std::this_thread::sleep_for(50ms)) {
    std::smatch m;
    const std::string log = Log();
    if (std::regex_search(log, m, line)) return std::stoll(m[1]);
  }
  return std::nullopt;
}

}  // namespace hg::testing
