#pragma once
/// @file
/// hullguardd as the end-to-end tests run it: on a config for a bounded time,
/// its stderr in a log file, gtest failures when it cannot start or logs no
/// scene epoch.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "publish/dds.h"
#include "support/daemon_process.h"

namespace hg::testing {

/// `qos` (a controller's reader QoS, which keeps the newest sample only) keeping
/// the last `depth` samples instead: a test that polls its readers may be
/// descheduled for longer than a cycle on a loaded machine, and must still see
/// every sample.
inline publish::dds::Qos KeepingLast(publish::dds::Qos qos, int depth = 256) {
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, depth);
  return qos;
}

class HullguarddRun : public DaemonProcess {
 public:
  /// `binary --config config --duration duration_s`, stderr in dir/hullguardd.log.
  HullguarddRun(const std::string& binary, const std::string& config, double duration_s,
                const std::filesystem::path& dir)
      : DaemonProcess(binary, {"--config", config, "--duration", std::to_string(duration_s)},
                      (dir / "hullguardd.log").string()) {
    EXPECT_TRUE(started()) << binary;
  }
  /// The CLOCK_REALTIME instant of scene time 0, from the daemon's log.
  [[nodiscard]] std::int64_t SceneEpoch() const {
    const std::optional<std::int64_t> epoch = SceneEpochNs();
    if (!epoch) ADD_FAILURE() << "no scene epoch in the daemon's log:\n" << Log();
    return epoch.value_or(0);
  }
};

}  // namespace hg::testing
