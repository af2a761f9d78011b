// DDS publisher tests: a DdsPublisher and readers in one process on loopback.
// Run through tests/publish/in_netns.sh (a private network namespace), never
// on the host network. With `--publish-seconds S --domain D` the binary
// instead publishes a small snapshot stream for the `hullguard echo` test.
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hullguard.h"
#include "publish/dds.h"
#include "publish/dds_publisher.h"

namespace hg::publish {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

// Samples are written only while fresh (PublisherConfig::max_age): stamps of now.
std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

int TestDomain() { return static_cast<int>(getpid() % 200) + 1; }

PublisherConfig TestConfig(const std::string& prefix) {
  PublisherConfig config;
  config.domain_id = TestDomain();
  config.topic_prefix = prefix;
  // Tests republish one snapshot until discovery is done, which may take
  // longer than the daemon's age limit on a loaded machine: no limit here
  // (the test of the limit sets it).
  config.max_age = std::chrono::nanoseconds(0);
  return config;
}

pipeline::OccupancySnapshot MakeSnapshot(std::uint64_t seed, std::size_t occupied,
                                         std::size_t occluded) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> cell(0, 511);
  pipeline::OccupancySnapshot s;
  s.sequence = seed * 7 + 3;
  s.stamp_ns = NowNs() + static_cast<std::int64_t>(seed);
  s.complete = (seed % 2) == 0;
  s.refined_cell_m = s.complete ? 0.03125 : 0.0625;
  // Not representable as floats: the sample carries the daemon's bounds exactly.
  s.bounds.min = {-2.3, -1.1, 0.1};
  s.bounds.max = {2.7, 3.9, 2.9};
  s.depth = 9;
  auto fill = [&](std::vector<pipeline::GridRun>& cells, std::size_t n) {
    cells.resize(n);
    for (pipeline::GridRun& c : cells) {
      c = {static_cast<std::uint16_t>(cell(rng)), static_cast<std::uint16_t>(cell(rng)),
           static_cast<std::uint16_t>(cell(rng)), static_cast<std::uint16_t>(1 + cell(rng) % 3)};
    }
  };
  fill(s.occupied, occupied);
  fill(s.occluded, occluded);
  s.health.degraded = (seed % 3) != 2;
  s.health.knowledge_filter = (seed % 2) == 1;
  s.health.filtered_m3 = s.health.knowledge_filter ? 0.0125 : 0.0;
  s.health.cameras = {
      {"cam_north", pipeline::CameraState::kOk, 29.5, 12.25, 1000, 3, 1},
      {"cam_south", pipeline::CameraState::kStale, 0.0, 450.5, 880, 0, 0},
      {"cam_über", pipeline::CameraState::kFailed, 0.0, 0.0, 0, 0, 7},
  };
  s.health.cameras[1].margin_m = 0.065;
  s.health.silhouette_ms = 4.5;
  s.health.octree_ms = 11.75;
  s.health.cycle_ms = 18.25;
  s.health.deadline_misses = 5;
  s.health.missed_cycles = 3;
  s.health.cycles = 1234;
  return s;
}

// Owned copies of received samples (the reader's loans are returned at once).
struct ReceivedOccupancy {
  hullguard_Occupancy header{};
  std::vector<hullguard_GridRun> occupied;
  std::vector<hullguard_GridRun> occluded;
};
struct ReceivedStatus {
  hullguard_Status header{};
  std::vector<hullguard_CameraStatus> cameras;
  std::vector<std::string> names;
};

// A reader of both topics on the test domain.
class TestSubscriber {
 public:
  TestSubscriber(const std::string& prefix, milliseconds deadline)
      : participant_(TestDomain()),
        occupancy_topic_(participant_, &hullguard_Occupancy_desc, OccupancyTopicName(prefix)),
        status_topic_(participant_, &hullguard_Status_desc, StatusTopicName(prefix)),
        occupancy_reader_(participant_, occupancy_topic_, OccupancyReaderQos(deadline).get()),
        status_reader_(participant_, status_topic_, StatusReaderQos(deadline).get()) {}

  const dds::Participant& participant() const { return participant_; }
  const dds::Reader& occupancy_reader() const { return occupancy_reader_; }

  bool TakeOccupancy(ReceivedOccupancy* out) {
    void* samples[1] = {nullptr};
    dds_sample_info_t info[1];
    const dds_return_t n = dds_take(occupancy_reader_.handle(), samples, info, 1, 1);
    if (n <= 0) return false;
    const bool valid = info[0].valid_data;
    if (valid) {
      const auto& s = *static_cast<const hullguard_Occupancy*>(samples[0]);
      out->header = s;
      out->occupied.assign(s.occupied._buffer, s.occupied._buffer + s.occupied._length);
      out->occluded.assign(s.occluded._buffer, s.occluded._buffer + s.occluded._length);
      out->header.occupied = {};
      out->header.occluded = {};
    }
    dds_return_loan(occupancy_reader_.handle(), samples, n);
    return valid;
  }

  bool TakeStatus(ReceivedStatus* out) {
    void* samples[1] = {nullptr};
    dds_sample_info_t info[1];
    const dds_return_t n = dds_take(status_reader_.handle(), samples, info, 1, 1);
    if (n <= 0) return false;
    const bool valid = info[0].valid_data;
    if (valid) {
      const auto& s = *static_cast<const hullguard_Status*>(samples[0]);
      out->header = s;
      out->cameras.assign(s.cameras._buffer, s.cameras._buffer + s.cameras._length);
      out->names.clear();
      for (hullguard_CameraStatus& c : out->cameras) {
        out->names.emplace_back(c.name);
        c.name = nullptr;
      }
      out->header.cameras = {};
    }
    dds_return_loan(status_reader_.handle(), samples, n);
    return valid;
  }

 private:
  dds::Participant participant_;
  dds::Topic occupancy_topic_;
  dds::Topic status_topic_;
  dds::Reader occupancy_reader_;
  dds::Reader status_reader_;
};

// Occupancy is best effort and discovery takes a moment, so publish again
// until both samples arrive (what a live daemon does every cycle anyway).
bool PublishUntilReceived(DdsPublisher& publisher, const pipeline::OccupancySnapshot& snapshot,
                          TestSubscriber& sub, ReceivedOccupancy* occ, ReceivedStatus* st) {
  bool got_occupancy = false;
  bool got_status = false;
  const auto give_up = std::chrono::steady_clock::now() + seconds(15);
  while (!(got_occupancy && got_status) && std::chrono::steady_clock::now() < give_up) {
    publisher.Publish(snapshot);
    std::this_thread::sleep_for(milliseconds(50));
    got_occupancy = sub.TakeOccupancy(occ) || got_occupancy;
    got_status = sub.TakeStatus(st) || got_status;
  }
  return got_occupancy && got_status;
}

void ExpectSameCells(const std::vector<pipeline::GridRun>& sent,
                     const std::vector<hullguard_GridRun>& received) {
  ASSERT_EQ(sent.size(), received.size());
  for (std::size_t i = 0; i < sent.size(); ++i) {
    ASSERT_EQ(sent[i].x, received[i].x) << i;
    ASSERT_EQ(sent[i].y, received[i].y) << i;
    ASSERT_EQ(sent[i].z, received[i].z) << i;
    ASSERT_EQ(sent[i].length, received[i].length) << i;
  }
}

void ExpectSameContent(const pipeline::OccupancySnapshot& sent, const ReceivedOccupancy& occ,
                       const ReceivedStatus& st) {
  EXPECT_EQ(occ.header.sequence, sent.sequence);
  EXPECT_EQ(occ.header.stamp_ns, sent.stamp_ns);
  EXPECT_EQ(occ.header.complete, sent.complete);
  EXPECT_EQ(occ.header.refined_cell_m, static_cast<float>(sent.refined_cell_m));
  EXPECT_EQ(occ.header.depth, sent.depth);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(occ.header.bounds_min[i], sent.bounds.min[i]);
    EXPECT_EQ(occ.header.bounds_max[i], sent.bounds.max[i]);
  }
  EXPECT_EQ(occ.header.knowledge_filter, sent.health.knowledge_filter);
  EXPECT_EQ(occ.header.filtered_m3, static_cast<float>(sent.health.filtered_m3));
  EXPECT_EQ(occ.header.degraded, sent.health.degraded);
  ExpectSameCells(sent.occupied, occ.occupied);
  ExpectSameCells(sent.occluded, occ.occluded);

  const pipeline::PipelineHealth& h = sent.health;
  EXPECT_EQ(st.header.sequence, sent.sequence);
  EXPECT_EQ(st.header.stamp_ns, sent.stamp_ns);
  EXPECT_EQ(st.header.degraded, h.degraded);
  EXPECT_EQ(st.header.silhouette_ms, static_cast<float>(h.silhouette_ms));
  EXPECT_EQ(st.header.octree_ms, static_cast<float>(h.octree_ms));
  EXPECT_EQ(st.header.cycle_ms, static_cast<float>(h.cycle_ms));
  EXPECT_EQ(st.header.deadline_misses, h.deadline_misses);
  EXPECT_EQ(st.header.missed_cycles, h.missed_cycles);
  EXPECT_EQ(st.header.cycles, h.cycles);
  ASSERT_EQ(st.cameras.size(), h.cameras.size());
  for (std::size_t i = 0; i < h.cameras.size(); ++i) {
    EXPECT_EQ(st.names[i], h.cameras[i].name);
    EXPECT_EQ(st.cameras[i].state, static_cast<std::uint8_t>(h.cameras[i].state));
    EXPECT_EQ(st.cameras[i].fps, static_cast<float>(h.cameras[i].fps));
    EXPECT_EQ(st.cameras[i].frame_age_ms, static_cast<float>(h.cameras[i].frame_age_ms));
    EXPECT_EQ(st.cameras[i].frames, h.cameras[i].frames);
    EXPECT_EQ(st.cameras[i].drops, h.cameras[i].drops);
    EXPECT_EQ(st.cameras[i].corrupt, h.cameras[i].corrupt);
    EXPECT_EQ(st.cameras[i].margin_m, static_cast<float>(h.cameras[i].margin_m));
  }
}

TEST(DdsPublisherTest, TopicNamesAndQosFollowTheRate) {
  EXPECT_EQ(OccupancyTopicName("hg"), "hg/occupancy");
  EXPECT_EQ(StatusTopicName("hg"), "hg/status");
  EXPECT_EQ(OfferedDeadline(20.0), milliseconds(100));
  EXPECT_EQ(OfferedLease(20.0), milliseconds(500));
  EXPECT_EQ(OfferedLease(5.0), seconds(2));
  EXPECT_THROW((void)OfferedDeadline(0.0), std::invalid_argument);

  dds::Qos qos = OccupancyWriterQos(20.0);
  dds_duration_t deadline = 0;
  ASSERT_TRUE(dds_qget_deadline(qos.get(), &deadline));
  EXPECT_EQ(deadline, DDS_MSECS(100));
  dds_reliability_kind_t reliability{};
  dds_duration_t blocking = -1;
  ASSERT_TRUE(dds_qget_reliability(qos.get(), &reliability, &blocking));
  EXPECT_EQ(reliability, DDS_RELIABILITY_BEST_EFFORT);
  qos = StatusWriterQos(20.0);
  ASSERT_TRUE(dds_qget_reliability(qos.get(), &reliability, &blocking));
  EXPECT_EQ(reliability, DDS_RELIABILITY_RELIABLE);
  EXPECT_EQ(blocking, 0);
  dds_liveliness_kind_t liveliness{};
  dds_duration_t lease = 0;
  ASSERT_TRUE(dds_qget_liveliness(qos.get(), &liveliness, &lease));
  EXPECT_EQ(liveliness, DDS_LIVELINESS_AUTOMATIC);
  EXPECT_EQ(lease, DDS_MSECS(500));
}

TEST(DdsPublisherTest, DisabledPublisherCreatesNothing) {
  PublisherConfig config = TestConfig("disabled");
  config.enabled = false;
  DdsPublisher publisher(config, 30.0);
  EXPECT_FALSE(publisher.enabled());
  publisher.Publish(MakeSnapshot(1, 10, 10));
  EXPECT_EQ(publisher.write_failures(), 0u);
}

TEST(DdsPublisherTest, BadDomainThrowsWithCycloneMessage) {
  PublisherConfig config = TestConfig("bad");
  config.domain_id = 100000;
  try {
    DdsPublisher publisher(config, 30.0);
    FAIL() << "expected dds::Error";
  } catch (const dds::Error& e) {
    EXPECT_NE(std::string(e.what()).find("dds_create_participant"), std::string::npos) << e.what();
    EXPECT_LT(e.code(), 0);
  }
}

TEST(DdsPublisherTest, PublishedSnapshotArrivesUnchanged) {
  DdsPublisher publisher(TestConfig("roundtrip"), 30.0);
  EXPECT_EQ(publisher.occupancy_topic(), "roundtrip/occupancy");
  TestSubscriber sub("roundtrip", milliseconds(1000));
  const pipeline::OccupancySnapshot sent = MakeSnapshot(42, 300, 77);
  ReceivedOccupancy occ;
  ReceivedStatus st;
  ASSERT_TRUE(PublishUntilReceived(publisher, sent, sub, &occ, &st));
  ExpectSameContent(sent, occ, st);

  // Smaller and then larger snapshots reuse and regrow the sample buffers.
  for (std::uint64_t seed : {43u, 44u}) {
    const pipeline::OccupancySnapshot next = MakeSnapshot(seed, seed == 43 ? 5 : 2000, 0);
    ASSERT_TRUE(PublishUntilReceived(publisher, next, sub, &occ, &st));
    ExpectSameContent(next, occ, st);
  }
  EXPECT_EQ(publisher.write_failures(), 0u);
}

TEST(DdsPublisherTest, HundredThousandCellsGoThrough) {
  DdsPublisher publisher(TestConfig("large"), 10.0);
  TestSubscriber sub("large", milliseconds(1000));
  const pipeline::OccupancySnapshot sent = MakeSnapshot(7, 100'000, 100'000);
  ReceivedOccupancy occ;
  ReceivedStatus st;
  ASSERT_TRUE(PublishUntilReceived(publisher, sent, sub, &occ, &st));
  ExpectSameContent(sent, occ, st);
}

TEST(DdsPublisherTest, ReaderSeesDeadlineMissWhenPublisherStops) {
  DdsPublisher publisher(TestConfig("deadline"), 50.0);  // Offers 40 ms.
  TestSubscriber sub("deadline", milliseconds(100));
  ReceivedOccupancy occ;
  ReceivedStatus st;
  ASSERT_TRUE(PublishUntilReceived(publisher, MakeSnapshot(1, 10, 0), sub, &occ, &st));

  const dds_entity_t reader = sub.occupancy_reader().handle();
  dds_requested_deadline_missed_status_t missed{};
  ASSERT_EQ(dds_get_requested_deadline_missed_status(reader, &missed), DDS_RETCODE_OK);
  ASSERT_EQ(dds_set_status_mask(reader, DDS_REQUESTED_DEADLINE_MISSED_STATUS), DDS_RETCODE_OK);
  dds::WaitSet waitset(sub.participant());
  waitset.Attach(sub.occupancy_reader(), 1);
  // The publisher is silent from here on; the miss must come within a few deadlines.
  std::array<dds_attach_t, 1> token{};
  ASSERT_EQ(waitset.Wait(token.data(), token.size(), seconds(5)), 1);
  ASSERT_EQ(dds_get_requested_deadline_missed_status(reader, &missed), DDS_RETCODE_OK);
  EXPECT_GE(missed.total_count, 1u);
  EXPECT_GE(missed.total_count_change, 1);
}

TEST(DdsPublisherTest, ReaderAskingForShorterDeadlineThanOfferedDoesNotMatch) {
  DdsPublisher publisher(TestConfig("rxo"), 10.0);  // Offers 200 ms.
  PublisherConfig config = TestConfig("rxo");
  dds::Participant participant(config.domain_id);
  dds::Topic topic(participant, &hullguard_Occupancy_desc, OccupancyTopicName("rxo"));
  dds::Reader reader(participant, topic, OccupancyReaderQos(milliseconds(50)).get());
  ASSERT_EQ(dds_set_status_mask(reader.handle(), DDS_REQUESTED_INCOMPATIBLE_QOS_STATUS),
            DDS_RETCODE_OK);
  dds::WaitSet waitset(participant);
  waitset.Attach(reader, 1);
  std::array<dds_attach_t, 1> token{};
  ASSERT_EQ(waitset.Wait(token.data(), token.size(), seconds(10)), 1);
  dds_requested_incompatible_qos_status_t incompatible{};
  ASSERT_EQ(dds_get_requested_incompatible_qos_status(reader.handle(), &incompatible),
            DDS_RETCODE_OK);
  EXPECT_GE(incompatible.total_count, 1u);
  EXPECT_EQ(incompatible.last_policy_id,
            static_cast<dds_qos_policy_id_t>(DDS_DEADLINE_QOS_POLICY_ID));
}

// A snapshot older than max_age when its turn comes (the daemon was stopped,
// SIGSTOP, and resumed) is not written: the reader gets the next fresh one.
TEST(DdsPublisherTest, ASnapshotOlderThanTheMaximumAgeIsNotWritten) {
  PublisherConfig config = TestConfig("stale");
  config.max_age = std::chrono::milliseconds(500);
  DdsPublisher publisher(config, 30.0);
  TestSubscriber sub("stale", milliseconds(1000));
  ReceivedOccupancy occ;
  ReceivedStatus st;
  ASSERT_TRUE(PublishUntilReceived(publisher, MakeSnapshot(1, 10, 0), sub, &occ, &st));
  while (sub.TakeOccupancy(&occ) || sub.TakeStatus(&st)) {
  }
  pipeline::OccupancySnapshot old = MakeSnapshot(2, 10, 0);
  old.stamp_ns -= 600'000'000;  // 0.6 s old.
  for (int i = 0; i < 5; ++i) publisher.Publish(old);
  std::this_thread::sleep_for(milliseconds(300));
  EXPECT_FALSE(sub.TakeOccupancy(&occ));
  EXPECT_FALSE(sub.TakeStatus(&st));
  EXPECT_EQ(publisher.stale_dropped(), 5u);
  const pipeline::OccupancySnapshot fresh = MakeSnapshot(3, 10, 0);
  ASSERT_TRUE(PublishUntilReceived(publisher, fresh, sub, &occ, &st));
  EXPECT_EQ(occ.header.sequence, fresh.sequence);
  EXPECT_EQ(publisher.stale_dropped(), 5u);
  EXPECT_EQ(publisher.write_failures(), 0u);
}

// The age limit follows the cameras: at least 0.5 s, else the longest camera
// timeout plus two cycles (cameras at 1.5 fps with a 1.5 s timeout had every
// other sample dropped while the status said ok).
TEST(DdsPublisherTest, MaxSampleAgeCoversTheLongestCameraTimeout) {
  using std::chrono::nanoseconds;
  EXPECT_EQ(MaxSampleAge(milliseconds(200), 30.0), nanoseconds(milliseconds(500)));
  EXPECT_EQ(MaxSampleAge(milliseconds(1500), 30.0), milliseconds(1500) + OfferedDeadline(30.0));
  EXPECT_EQ(MaxSampleAge(milliseconds(400), 5.0), milliseconds(800));
}

// A second publisher under the same prefix on the domain (another daemon
// with a copied config) is noticed: every status sample says degraded while
// it is there, and not once it is gone.
TEST(DdsPublisherTest, AnotherPublisherOfTheSameTopicsMakesTheStatusDegraded) {
  DdsPublisher publisher(TestConfig("twice"), 30.0);
  EXPECT_EQ(publisher.CheckOtherPublishers(), 0);
  TestSubscriber sub("twice", milliseconds(1000));
  pipeline::OccupancySnapshot s = MakeSnapshot(2, 10, 0);
  s.health.degraded = false;
  ReceivedOccupancy occ;
  ReceivedStatus st;
  ASSERT_TRUE(PublishUntilReceived(publisher, s, sub, &occ, &st));
  EXPECT_FALSE(st.header.degraded);
  EXPECT_FALSE(occ.header.degraded);
  {
    DdsPublisher other(TestConfig("twice"), 30.0);
    int others = 0;
    for (int i = 0; i < 200 && others == 0; ++i) {
      std::this_thread::sleep_for(milliseconds(25));
      others = publisher.CheckOtherPublishers();
    }
    ASSERT_EQ(others, 1);
    EXPECT_EQ(other.CheckOtherPublishers(), 1);
    while (sub.TakeStatus(&st)) {
    }
    s = MakeSnapshot(2, 10, 0);
    s.health.degraded = false;
    ASSERT_TRUE(PublishUntilReceived(publisher, s, sub, &occ, &st));
    EXPECT_TRUE(st.header.degraded);
    EXPECT_TRUE(occ.header.degraded);
  }
  int others = 1;
  for (int i = 0; i < 200 && others != 0; ++i) {
    std::this_thread::sleep_for(milliseconds(25));
    others = publisher.CheckOtherPublishers();
  }
  EXPECT_EQ(others, 0);
  s = MakeSnapshot(2, 10, 0);
  s.health.degraded = false;
  ASSERT_TRUE(PublishUntilReceived(publisher, s, sub, &occ, &st));
  EXPECT_FALSE(st.header.degraded);
  EXPECT_FALSE(occ.header.degraded);

  // A best-effort writer of the status topic (another tool, not a daemon)
  // counts too.
  {
    dds::Participant participant(static_cast<dds_domainid_t>(TestDomain()));
    dds::Topic topic(participant, &hullguard_Status_desc, StatusTopicName("twice"));
    dds::Qos qos;
    dds_qset_reliability(qos.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
    dds::Writer writer(participant, topic, qos.get());
    others = 0;
    for (int i = 0; i < 200 && others == 0; ++i) {
      std::this_thread::sleep_for(milliseconds(25));
      others = publisher.CheckOtherPublishers();
    }
    EXPECT_EQ(others, 1);
  }
  for (int i = 0; i < 200 && others != 0; ++i) {
    std::this_thread::sleep_for(milliseconds(25));
    others = publisher.CheckOtherPublishers();
  }
  EXPECT_EQ(others, 0);
  // So does a writer of the occupancy topic alone (a tool replaying
  // occupancy under the daemon's prefix), which a controller would take for
  // the daemon's: noticed, and its samples make the status degraded.
  {
    dds::Participant participant(static_cast<dds_domainid_t>(TestDomain()));
    dds::Topic topic(participant, &hullguard_Occupancy_desc, OccupancyTopicName("twice"));
    dds::Writer writer(participant, topic, OccupancyWriterQos(30.0).get());
    others = 0;
    for (int i = 0; i < 200 && others == 0; ++i) {
      std::this_thread::sleep_for(milliseconds(25));
      others = publisher.CheckOtherPublishers();
    }
    EXPECT_EQ(others, 1);
    while (sub.TakeStatus(&st)) {
    }
    s = MakeSnapshot(2, 10, 0);
    s.health.degraded = false;
    ASSERT_TRUE(PublishUntilReceived(publisher, s, sub, &occ, &st));
    EXPECT_TRUE(st.header.degraded);
    EXPECT_TRUE(occ.header.degraded);
  }
}

// Publisher mode for the `hullguard echo` test: 20 Hz for `seconds_to_run`.
int PublishForEcho(int domain, double seconds_to_run) {
  PublisherConfig config;
  config.domain_id = domain;
  DdsPublisher publisher(config, 20.0);
  const auto end = std::chrono::steady_clock::now() +
                   std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                       std::chrono::duration<double>(seconds_to_run));
  for (std::uint64_t i = 0; std::chrono::steady_clock::now() < end; ++i) {
    pipeline::OccupancySnapshot s = MakeSnapshot(i, 64, 8);
    s.sequence = i;
    publisher.Publish(s);
    std::this_thread::sleep_for(milliseconds(50));
  }
  return 0;
}

}  // namespace
}  // namespace hg::publish

int main(int argc, char** argv) {
  if (argc == 5 && std::strcmp(argv[1], "--publish-seconds") == 0 &&
      std::strcmp(argv[3], "--domain") == 0) {
    return hg::publish::PublishForEcho(std::atoi(argv[4]), std::atof(argv[2]));
  }
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
