#pragma once
/// @file
/// Publishes each OccupancySnapshot over Cyclone DDS as two keyless topics,
/// "<prefix>/occupancy" (hullguard::Occupancy) and "<prefix>/status"
/// (hullguard::Status), and the tracked people of a cycle as "<prefix>/tracks"
/// (hullguard::Tracks), with QoS that lets a controller tell a live stream
/// from a stale one (deadline and liveliness). See docs/dds.md.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "pipeline/snapshot.h"
#include "publish/dds.h"
#include "tracking/tracker.h"

namespace hg::publish {

/// Where the publisher writes (the daemon fills it from its `dds` section).
struct PublisherConfig {
  int domain_id = 0;
  std::string topic_prefix = "hullguard";
  bool enabled = true;  ///< False: Publish() does nothing.
  /// Creates the tracks topic and writer (the daemon's tracking.enabled);
  /// false: PublishTracks() does nothing.
  bool tracks = true;
  /// A snapshot (or tracks sample) whose stamp is older than this when its
  /// turn to be written comes is not written (counted in stale_dropped()):
  /// after the process was stopped (SIGSTOP, a debugger, a frozen VM) or
  /// starved, the first sample would otherwise describe the cell as it was
  /// then. Zero: no limit. The daemon takes the longer of kMinMaxAge and
  /// its longest camera timeout plus two cycles (MaxSampleAge): a camera that
  /// is ok by its own timeout keeps its samples published.
  std::chrono::nanoseconds max_age = kMinMaxAge;
  static constexpr std::chrono::milliseconds kMinMaxAge{500};
};

/// The max_age for a daemon whose longest camera timeout is
/// `longest_camera_timeout` at `rate_hz`: the longer of
/// PublisherConfig::kMinMaxAge and that timeout plus two cycles. A sample of
/// frames each within its camera's timeout is published however slow the
/// cameras (1.5 fps with a 1.5 s timeout: samples 0.7 s old were dropped).
[[nodiscard]] std::chrono::nanoseconds MaxSampleAge(
    std::chrono::milliseconds longest_camera_timeout, double rate_hz);

/// Topic names for a prefix ("hullguard" -> "hullguard/occupancy").
[[nodiscard]] std::string OccupancyTopicName(const std::string& prefix);
[[nodiscard]] std::string StatusTopicName(const std::string& prefix);
[[nodiscard]] std::string TracksTopicName(const std::string& prefix);

/// The deadline the writers offer at a fusion rate: two cycles. A reader must
/// request a period at least this long to match.
[[nodiscard]] std::chrono::nanoseconds OfferedDeadline(double rate_hz);

/// The liveliness lease the writers offer at a fusion rate (automatic
/// liveliness): ten cycles, at least 500 ms.
[[nodiscard]] std::chrono::nanoseconds OfferedLease(double rate_hz);

/// Writer QoS. Occupancy: best effort, keep last 1, volatile. Status:
/// reliable (never blocking the caller), keep last 1, volatile. Both: deadline
/// OfferedDeadline, automatic liveliness with OfferedLease.
[[nodiscard]] dds::Qos OccupancyWriterQos(double rate_hz);
[[nodiscard]] dds::Qos StatusWriterQos(double rate_hz);
/// Tracks: as status (reliable, never blocking the caller).
[[nodiscard]] dds::Qos TracksWriterQos(double rate_hz);

/// Reader QoS matching the writers, requesting `deadline` (must be >= the
/// writer's OfferedDeadline to match). Occupancy: best effort; status:
/// reliable. Liveliness is left at automatic/infinite, which matches any lease.
[[nodiscard]] dds::Qos OccupancyReaderQos(std::chrono::nanoseconds deadline);
[[nodiscard]] dds::Qos StatusReaderQos(std::chrono::nanoseconds deadline);
[[nodiscard]] dds::Qos TracksReaderQos(std::chrono::nanoseconds deadline);

/// Writes occupancy and status for each snapshot, and tracks for each tracked cycle.
///
/// Sample buffers are owned and reused: after the first snapshots have grown
/// them to the largest cell and camera counts seen, Publish allocates nothing
/// itself (camera names point into the snapshot). Cyclone DDS still allocates
/// a serialized copy of each sample inside dds_write (see docs/dds.md).
///
/// Thread safety: Publish from one thread (the fusion thread) and
/// PublishTracks from one thread (the tracking thread; may be another): the two
/// share only the participant, which Cyclone DDS makes thread-safe.
class DdsPublisher {
 public:
  /// Creates the participant on `config.domain_id`, the three topics under
  /// `config.topic_prefix`, and their writers, with QoS derived from the
  /// fusion rate `rate_hz` (> 0). When `config.enabled` is false nothing is
  /// created and Publish and PublishTracks do nothing.
  /// @throws dds::Error when Cyclone DDS refuses (bad domain, bad topic name,
  /// bad CYCLONEDDS_URI); std::invalid_argument when rate_hz <= 0.
  DdsPublisher(const PublisherConfig& config, double rate_hz);
  ~DdsPublisher();
  DdsPublisher(const DdsPublisher&) = delete;
  DdsPublisher& operator=(const DdsPublisher&) = delete;

  /// Writes the occupancy and the status of `snapshot`. Never throws and never
  /// blocks on slow readers: a failed write is counted in write_failures().
  void Publish(const pipeline::OccupancySnapshot& snapshot);

  /// Writes one Tracks sample: the tracks of the occupancy cycle `sequence`
  /// (stamp and degraded flag of that cycle). Never throws and never blocks;
  /// after the buffer has grown to the largest track count seen it allocates
  /// nothing itself. A failed write is counted in tracks_write_failures().
  void PublishTracks(std::uint64_t sequence, std::int64_t stamp_ns, bool degraded,
                     std::span<const tracking::Track> tracks);

  /// Writes refused by Cyclone DDS since construction (a runtime fault: the
  /// daemon logs it and its health line says DEGRADED; a failed occupancy
  /// write also makes that cycle's status sample degraded). Thread-safe.
  [[nodiscard]] std::uint64_t write_failures() const {
    return write_failures_.load(std::memory_order_relaxed);
  }
  /// Tracks writes refused since construction. Thread-safe.
  [[nodiscard]] std::uint64_t tracks_write_failures() const {
    return tracks_write_failures_.load(std::memory_order_relaxed);
  }

  /// Snapshots and tracks samples not written because they were older than
  /// PublisherConfig::max_age. Thread-safe.
  [[nodiscard]] std::uint64_t stale_dropped() const {
    return stale_dropped_.load(std::memory_order_relaxed);
  }

  /// Writers of this publisher's status or occupancy topic other than its
  /// own, on its domain (the larger of the two counts): another publisher
  /// under the same prefix (a second daemon, a config copied from another
  /// cell, or some other tool writing occupancy), whose samples a controller
  /// could not tell from this one's. 0 when disabled. While it is not 0 every status
  /// sample says degraded. Thread-safe; call it at most every few hundred
  /// milliseconds (it asks Cyclone DDS for the matched writers and updates
  /// the flag Publish() reads).
  [[nodiscard]] int CheckOtherPublishers();

  [[nodiscard]] bool enabled() const { return enabled_; }
  [[nodiscard]] const std::string& occupancy_topic() const { return occupancy_topic_; }
  [[nodiscard]] const std::string& status_topic() const { return status_topic_; }
  [[nodiscard]] const std::string& tracks_topic() const { return tracks_topic_; }

 private:
  struct Samples;        // idlc-generated samples and their reused buffers.
  struct TracksSamples;  // The same for PublishTracks (its own thread).
  /// Whether a sample stamped `stamp_ns` is older than max_age_ (counted).
  bool TooOld(std::int64_t stamp_ns);

  bool enabled_;
  std::string occupancy_topic_;
  std::string status_topic_;
  std::string tracks_topic_;
  // The participant is declared first so it is deleted last (after its children).
  dds::Participant participant_;
  dds::Topic occupancy_topic_entity_;
  dds::Topic status_topic_entity_;
  dds::Topic tracks_topic_entity_;
  dds::Writer occupancy_writer_;
  dds::Writer status_writer_;
  dds::Writer tracks_writer_;
  /// Read nothing: their matched writers tell CheckOtherPublishers() who
  /// else writes the status and the occupancy topics.
  dds::Reader status_watch_;
  dds::Reader occupancy_watch_;
  std::chrono::nanoseconds max_age_;
  std::atomic<bool> other_publishers_{false};
  std::atomic<std::uint64_t> stale_dropped_{0};
  std::unique_ptr<Samples> samples_;
  std::unique_ptr<TracksSamples> tracks_samples_;
  std::atomic<std::uint64_t> write_failures_{0};  // Written by Publish(), read from any thread.
  std::atomic<std::uint64_t> tracks_write_failures_{0};
};

}  // namespace hg::publish
