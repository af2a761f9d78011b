#include "common/log.h"

#include <memory>

#include <spdlog/logger.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/sinks/systemd_sink.h>

namespace hg::log {
namespace {

spdlog::level::level_enum ToSpdlog(Level level) {
  switch (level) {
    case Level::kTrace:
      return spdlog::level::trace;
    case Level::kDebug:
      return spdlog::level::debug;
    case Level::kInfo:
      return spdlog::level::info;
    case Level::kWarn:
      return spdlog::level::warn;
    case Level::kError:
      return spdlog::level::err;
  }
  return spdlog::level::info;
}

std::shared_ptr<spdlog::logger> Make(std::string name, Level level, Sink sink) {
  std::shared_ptr<spdlog::logger> logger;
  if (sink == Sink::kJournal) {
    // The journal keeps the priority and the identifier as fields: the text
    // goes in alone.
    logger = std::make_shared<spdlog::logger>(std::move(name),
                                              std::make_shared<spdlog::sinks::systemd_sink_mt>());
  } else {
    logger = std::make_shared<spdlog::logger>(std::move(name),
                                              std::make_shared<spdlog::sinks::stderr_sink_mt>());
    logger->set_pattern("%n: %v");
  }
  logger->set_level(ToSpdlog(level));
  // Every line reaches its destination before the next one is formatted: a
  // crash right after loses nothing, and lines of several threads stay whole.
  logger->flush_on(spdlog::level::trace);
  return logger;
}

std::shared_ptr<spdlog::logger>& Current() {
  static std::shared_ptr<spdlog::logger> logger = Make("hullguard", Level::kInfo, Sink::kStderr);
  return logger;
}

}  // namespace

void Configure(std::string name, Level level, Sink sink) {
  Current() = Make(std::move(name), level, sink);
}

bool Enabled(Level level) { return Current()->should_log(ToSpdlog(level)); }

void Write(Level level, std::string_view text) { Current()->log(ToSpdlog(level), text); }

}  // namespace hg::log
