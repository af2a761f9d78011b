#pragma once
/// @file
/// Logging facade: one process-wide logger over spdlog, writing to stderr or
/// to the systemd journal. Not for the per-frame hot path (a line is
/// formatted into a string).

#include <string>
#include <string_view>
#include <utility>

#include <fmt/format.h>

namespace hg::log {

/// Severity, least to most.
enum class Level { kTrace, kDebug, kInfo, kWarn, kError };

/// Where lines go.
enum class Sink {
  kStderr,   ///< "<name>: <text>", one line each (under systemd also in the journal).
  kJournal,  ///< Journal entries with their priority and SYSLOG_IDENTIFIER=<name>.
};

/// Replaces the logger: lines below `level` are dropped. Call at start-up,
/// before other threads log. Without a call: stderr, level info, the name
/// "hullguard".
void Configure(std::string name, Level level, Sink sink);

/// Whether a line of `level` would be written.
[[nodiscard]] bool Enabled(Level level);

/// Writes one line. Thread-safe.
void Write(Level level, std::string_view text);

template <class... Args>
void Debug(fmt::format_string<Args...> format, Args&&... args) {
  if (Enabled(Level::kDebug))
    Write(Level::kDebug, fmt::format(format, std::forward<Args>(args)...));
}
template <class... Args>
void Info(fmt::format_string<Args...> format, Args&&... args) {
  if (Enabled(Level::kInfo)) Write(Level::kInfo, fmt::format(format, std::forward<Args>(args)...));
}
template <class... Args>
void Warn(fmt::format_string<Args...> format, Args&&... args) {
  if (Enabled(Level::kWarn)) Write(Level::kWarn, fmt::format(format, std::forward<Args>(args)...));
}
template <class... Args>
void Error(fmt::format_string<Args...> format, Args&&... args) {
  if (Enabled(Level::kError))
    Write(Level::kError, fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace hg::log
