#include "publish/dds_publisher.h"

#include <time.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <vector>

#include "hullguard.h"

namespace hg::publish {
namespace {

using std::chrono::nanoseconds;

nanoseconds CyclePeriod(double rate_hz) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    throw std::invalid_argument("DdsPublisher: rate_hz must be > 0, got " +
                                std::to_string(rate_hz));
  }
  return nanoseconds(static_cast<std::int64_t>(std::llround(1e9 / rate_hz)));
}

// Settings shared by every writer and reader: keep only the newest sample
// (older ones are useless to a controller), volatile (a late joiner must wait
// for a fresh cycle rather than act on an old one).
void SetCommon(const dds::Qos& qos) {
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
  dds_qset_durability(qos.get(), DDS_DURABILITY_VOLATILE);
}

dds::Qos WriterQos(double rate_hz, dds_reliability_kind_t reliability) {
  dds::Qos qos;
  SetCommon(qos);
  // max_blocking_time 0: a reliable write whose history is full fails at once
  // (counted) instead of stalling the fusion thread.
  dds_qset_reliability(qos.get(), reliability, 0);
  dds_qset_deadline(qos.get(), dds::ToDuration(OfferedDeadline(rate_hz)));
  dds_qset_liveliness(qos.get(), DDS_LIVELINESS_AUTOMATIC, dds::ToDuration(OfferedLease(rate_hz)));
  return qos;
}

dds::Qos ReaderQos(nanoseconds deadline, dds_reliability_kind_t reliability) {
  dds::Qos qos;
  SetCommon(qos);
  dds_qset_reliability(qos.get(), reliability, DDS_MSECS(100));
  dds_qset_deadline(qos.get(), dds::ToDuration(deadline));
  return qos;
}

template <typename Seq, typename T>
void Grow(Seq& seq, std::vector<T>& storage, std::size_t n) {
  if (storage.size() < n) storage.resize(n);
  seq._buffer = storage.data();
  seq._maximum = static_cast<std::uint32_t>(storage.size());
  seq._length = static_cast<std::uint32_t>(n);
  seq._release = false;  // The vector owns the buffer, not Cyclone DDS.
}

void FillCells(const std::vector<pipeline::GridRun>& runs, dds_sequence_hullguard_GridRun& seq,
               std::vector<hullguard_GridRun>& storage) {
  Grow(seq, storage, runs.size());
  for (std::size_t i = 0; i < runs.size(); ++i) {
    storage[i] = hullguard_GridRun{runs[i].x, runs[i].y, runs[i].z, runs[i].length};
  }
}

}  // namespace

struct DdsPublisher::Samples {
  hullguard_Occupancy occupancy{};
  hullguard_Status status{};
  std::vector<hullguard_GridRun> occupied;
  std::vector<hullguard_GridRun> occluded;
  std::vector<hullguard_CameraStatus> cameras;
};

struct DdsPublisher::TracksSamples {
  hullguard_Tracks tracks{};
  std::vector<hullguard_Track> storage;
};

std::string OccupancyTopicName(const std::string& prefix) { return prefix + "/occupancy"; }
std::string StatusTopicName(const std::string& prefix) { return prefix + "/status"; }
std::string TracksTopicName(const std::string& prefix) { return prefix + "/tracks"; }

nanoseconds OfferedDeadline(double rate_hz) { return 2 * CyclePeriod(rate_hz); }

nanoseconds OfferedLease(double rate_hz) {
  return std::max<nanoseconds>(10 * CyclePeriod(rate_hz), std::chrono::milliseconds(500));
}

dds::Qos OccupancyWriterQos(double rate_hz) {
  return WriterQos(rate_hz, DDS_RELIABILITY_BEST_EFFORT);
}
dds::Qos StatusWriterQos(double rate_hz) { return WriterQos(rate_hz, DDS_RELIABILITY_RELIABLE); }
dds::Qos TracksWriterQos(double rate_hz) { return WriterQos(rate_hz, DDS_RELIABILITY_RELIABLE); }
dds::Qos OccupancyReaderQos(nanoseconds deadline) {
  return ReaderQos(deadline, DDS_RELIABILITY_BEST_EFFORT);
}
dds::Qos StatusReaderQos(nanoseconds deadline) {
  return ReaderQos(deadline, DDS_RELIABILITY_RELIABLE);
}
dds::Qos TracksReaderQos(nanoseconds deadline) {
  return ReaderQos(deadline, DDS_RELIABILITY_RELIABLE);
}

DdsPublisher::DdsPublisher(const PublisherConfig& config, double rate_hz)
    : enabled_(config.enabled),
      occupancy_topic_(OccupancyTopicName(config.topic_prefix)),
      status_topic_(StatusTopicName(config.topic_prefix)),
      tracks_topic_(TracksTopicName(config.topic_prefix)),
      max_age_(config.max_age),
      samples_(std::make_unique<Samples>()),
      tracks_samples_(std::make_unique<TracksSamples>()) {
  CyclePeriod(rate_hz);  // Validates the rate even when disabled.
  if (!enabled_) return;
  participant_ = dds::Participant(static_cast<dds_domainid_t>(config.domain_id));
  occupancy_topic_entity_ = dds::Topic(participant_, &hullguard_Occupancy_desc, occupancy_topic_);
  status_topic_entity_ = dds::Topic(participant_, &hullguard_Status_desc, status_topic_);
  occupancy_writer_ =
      dds::Writer(participant_, occupancy_topic_entity_, OccupancyWriterQos(rate_hz).get());
  status_writer_ = dds::Writer(participant_, status_topic_entity_, StatusWriterQos(rate_hz).get());
  {
    // Best effort, volatile, no deadline: requests nothing a writer could
    // fail to offer, so it matches every writer of the topic, reliable or
    // not. Its own participant's writers are ignored, so that the daemon's
    // own samples are not delivered to it every cycle (it never reads);
    // another's are, into a history of one, only while there is one.
    dds::Qos qos;
    SetCommon(qos);
    dds_qset_reliability(qos.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
    dds_qset_ignorelocal(qos.get(), DDS_IGNORELOCAL_PARTICIPANT);
    status_watch_ = dds::Reader(participant_, status_topic_entity_, qos.get());
    occupancy_watch_ = dds::Reader(participant_, occupancy_topic_entity_, qos.get());
  }
  if (config.tracks) {
    tracks_topic_entity_ = dds::Topic(participant_, &hullguard_Tracks_desc, tracks_topic_);
    tracks_writer_ =
        dds::Writer(participant_, tracks_topic_entity_, TracksWriterQos(rate_hz).get());
  }
}

DdsPublisher::~DdsPublisher() = default;

std::chrono::nanoseconds MaxSampleAge(std::chrono::milliseconds longest_camera_timeout,
                                      double rate_hz) {
  const std::chrono::nanoseconds cycles = OfferedDeadline(rate_hz);
  return std::max<std::chrono::nanoseconds>(PublisherConfig::kMinMaxAge,
                                            longest_camera_timeout + cycles);
}

bool DdsPublisher::TooOld(std::int64_t stamp_ns) {
  if (max_age_.count() <= 0) return false;
  timespec now{};
  clock_gettime(CLOCK_REALTIME, &now);
  const std::int64_t now_ns = static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
  if (now_ns - stamp_ns <= max_age_.count()) return false;
  stale_dropped_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

namespace {

/// Writers matched by `watch` other than `own`; -1 when Cyclone DDS cannot say.
int OtherWriters(const dds::Reader& watch, const dds::Writer& own_writer) {
  dds_instance_handle_t own = 0;
  if (dds_get_instance_handle(own_writer.handle(), &own) < 0) return -1;
  std::array<dds_instance_handle_t, 16> matched{};
  const dds_return_t n =
      dds_get_matched_publications(watch.handle(), matched.data(), matched.size());
  if (n < 0) return -1;
  // n may exceed what fits: every writer beyond the array is another's.
  int others = std::max(0, static_cast<int>(n) - static_cast<int>(matched.size()));
  for (std::size_t i = 0; i < std::min<std::size_t>(static_cast<std::size_t>(n), matched.size());
       ++i) {
    others += matched[i] != own ? 1 : 0;
  }
  return others;
}

}  // namespace

int DdsPublisher::CheckOtherPublishers() {
  if (!status_watch_ || !occupancy_watch_) return 0;
  const int others = std::max({0, OtherWriters(status_watch_, status_writer_),
                               OtherWriters(occupancy_watch_, occupancy_writer_)});
  other_publishers_.store(others > 0, std::memory_order_relaxed);
  return others;
}

void DdsPublisher::Publish(const pipeline::OccupancySnapshot& snapshot) {
  if (!enabled_) return;
  if (TooOld(snapshot.stamp_ns)) return;
  Samples& s = *samples_;

  hullguard_Occupancy& occ = s.occupancy;
  occ.sequence = snapshot.sequence;
  occ.stamp_ns = snapshot.stamp_ns;
  occ.complete = snapshot.complete;
  occ.refined_cell_m = static_cast<float>(snapshot.refined_cell_m);
  for (int i = 0; i < 3; ++i) {
    occ.bounds_min[i] = snapshot.bounds.min[i];
    occ.bounds_max[i] = snapshot.bounds.max[i];
  }
  occ.depth = static_cast<std::uint8_t>(snapshot.depth);
  occ.knowledge_filter = snapshot.health.knowledge_filter;
  occ.filtered_m3 = static_cast<float>(snapshot.health.filtered_m3);
  // As the status sample of this cycle says (below, which adds a failed
  // occupancy write).
  occ.degraded = snapshot.health.degraded || other_publishers_.load(std::memory_order_relaxed);
  FillCells(snapshot.occupied, occ.occupied, s.occupied);
  FillCells(snapshot.occluded, occ.occluded, s.occluded);

  const pipeline::PipelineHealth& health = snapshot.health;
  hullguard_Status& st = s.status;
  st.sequence = snapshot.sequence;
  st.stamp_ns = snapshot.stamp_ns;
  // The occupancy goes first: a controller that gets this cycle's status but
  // not its occupancy (the write failed) reads degraded.
  const bool occupancy_written = occupancy_writer_.Write(&occ) >= 0;
  if (!occupancy_written) write_failures_.fetch_add(1, std::memory_order_relaxed);
  st.degraded = occ.degraded || !occupancy_written;
  Grow(st.cameras, s.cameras, health.cameras.size());
  for (std::size_t i = 0; i < health.cameras.size(); ++i) {
    const pipeline::CameraHealth& c = health.cameras[i];
    hullguard_CameraStatus& out = s.cameras[i];
    // Only read during dds_write, while the snapshot is alive.
    out.name = const_cast<char*>(c.name.c_str());
    out.state = static_cast<std::uint8_t>(c.state);
    out.fps = static_cast<float>(c.fps);
    out.frame_age_ms = static_cast<float>(c.frame_age_ms);
    out.frames = c.frames;
    out.drops = c.drops;
    out.corrupt = c.corrupt;
    out.fault = c.fault;
    out.completed = c.completed;
    out.failed = c.failed;
    out.underruns = c.underruns;
    out.resends = c.resends;
    out.margin_m = static_cast<float>(c.margin_m);
  }
  st.silhouette_ms = static_cast<float>(health.silhouette_ms);
  st.skew_ms = static_cast<float>(health.skew_ms);
  st.octree_ms = static_cast<float>(health.octree_ms);
  st.cycle_ms = static_cast<float>(health.cycle_ms);
  st.deadline_misses = health.deadline_misses;
  st.cycles = health.cycles;
  st.missed_cycles = health.missed_cycles;

  if (status_writer_.Write(&st) < 0) write_failures_.fetch_add(1, std::memory_order_relaxed);
}

void DdsPublisher::PublishTracks(std::uint64_t sequence, std::int64_t stamp_ns, bool degraded,
                                 std::span<const tracking::Track> tracks) {
  if (!tracks_writer_) return;
  if (TooOld(stamp_ns)) return;
  TracksSamples& s = *tracks_samples_;
  hullguard_Tracks& out = s.tracks;
  out.sequence = sequence;
  out.stamp_ns = stamp_ns;
  // As the cycle's status sample says (Publish()).
  out.degraded = degraded || other_publishers_.load(std::memory_order_relaxed);
  Grow(out.tracked, s.storage, tracks.size());
  for (std::size_t i = 0; i < tracks.size(); ++i) {
    const tracking::Track& t = tracks[i];
    hullguard_Track& o = s.storage[i];
    o.id = t.id;
    for (int k = 0; k < 3; ++k) {
      o.centre[k] = static_cast<float>(t.centre_W[k]);
      o.half_axes[k] = static_cast<float>(t.half_axes_m[k]);
      o.velocity[k] = static_cast<float>(t.velocity_W_mps[k]);
      o.spread[k] = static_cast<float>(std::sqrt(std::max(0.0, t.centre_covariance_m2(k, k))));
    }
    o.occluded = t.occluded;
    o.occluded_fraction = static_cast<float>(t.occluded_fraction);
    o.age_s = static_cast<float>(t.age_s);
    o.time_since_support_s = static_cast<float>(t.time_since_support_s);
  }
  if (tracks_writer_.Write(&out) < 0) {
    tracks_write_failures_.fetch_add(1, std::memory_order_relaxed);
  }
}

}  // namespace hg::publish
