// recorder and recording_player actors in a real runtime: the recorder subscribes to a topic
// without knowing its type, the player republishes it to typed subscribers with the same bytes
// and stamps; type mismatches between a recording and a profile are wiring errors.
#include "../../runtime/test_actors.hpp"

#include <tessera/players/recording_actors.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <filesystem>

using namespace tessera;
using namespace tessera::players;
namespace fs = std::filesystem;

namespace {
RuntimeOptions quiet() {
  RuntimeOptions o;
  o.show_progress = false;
  o.threads = 2;
  return o;
}

/// Subscribes to "in" as LaserScan (to check the player's type against the subscriber's).
class ScanSink : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::LaserScan>("in", MailboxPolicy::reliable(), [](const auto&) {});
  }
};
}  // namespace

TEST_CASE("recorder records a topic of any type and recording_player republishes it",
          "[recording]") {
  const fs::path dir = fs::temp_directory_path() / "tessera_recording_actors";
  fs::remove_all(dir);
  fs::create_directories(dir);
  RecorderOptions ro;
  ro.path = "blobs.trec";  // relative: into the run's output folder
  ro.topics = {"blobs"};
  ro.block_kib = 2;

  std::vector<std::shared_ptr<const MessageStorage>> originals;
  {
    auto options = quiet();
    options.output_dir = dir.string();
    Runtime rt(options);
    // The untyped subscriber is configured before the publisher: the topic's type comes later.
    rt.add("rec", std::make_unique<RecorderActor>(ro));
    rt.add("src", std::make_unique<test::CountingSource>(50, 10'000'000, 300), {{"out", "blobs"}});
    auto& sink = static_cast<test::Recorder&>(rt.add(
        "sink", std::make_unique<test::Recorder>(MailboxPolicy::reliable()), {{"in", "blobs"}}));
    const auto report = rt.run();
    REQUIRE(sink.seqs.size() == 50);
    for (const auto& a : report.actors) {
      if (a.name != "rec") continue;
      CHECK(std::get<std::int64_t>(a.summary.at("messages")) == 50);
      CHECK(std::get<std::int64_t>(a.summary.at("blocks")) > 3);
      CHECK(std::get<std::string>(a.summary.at("error")).empty());
    }
  }
  const fs::path file = dir / "blobs.trec";
  {
    RecordingReader reader(file.string());
    REQUIRE(reader.topics().size() == 1);
    CHECK(reader.topics()[0].type_id == messageTypeOf<msg::Blob>().id);
    CHECK(reader.topics()[0].type_name == "Blob");
    RecordedMessage m;
    std::int64_t k = 0;
    while (reader.next(m)) {
      // Stamps are the runtime time of delivery: the source publishes at k * 10 ms.
      CHECK(m.stamp == k * 10'000'000);
      CHECK(Message<msg::Blob>(m.message)->getHeader().getSeq() == static_cast<std::uint64_t>(k));
      ++k;
    }
    CHECK(k == 50);
    CHECK(reader.losses().empty());
  }
  {
    Runtime rt(quiet());
    RecordingPlayerOptions po;
    po.path = file.string();
    rt.add("play", std::make_unique<RecordingPlayer>(po));
    auto& sink = static_cast<test::Recorder&>(rt.add(
        "sink", std::make_unique<test::Recorder>(MailboxPolicy::reliable()), {{"in", "blobs"}}));
    const auto report = rt.run();
    REQUIRE(sink.seqs.size() == 50);
    for (std::size_t i = 0; i < 50; ++i) {
      CHECK(sink.seqs[i] == i);
      CHECK(sink.stamps[i] == static_cast<Nanos>(i) * 10'000'000);
    }
    // Recorded 10 ms apart, replayed 10 ms apart on the simulated clock.
    CHECK(report.sim_duration_s == Approx(0.49).margin(1e-9));
  }
  {
    Runtime rt(quiet());
    RecordingPlayerOptions po;
    po.path = file.string();
    rt.add("play", std::make_unique<RecordingPlayer>(po));
    rt.add("scans", std::make_unique<ScanSink>(), {{"in", "blobs"}});
    CHECK_THROWS_WITH(rt.configure(), Catch::Contains("Blob") && Catch::Contains("LaserScan"));
  }
  {
    RecordingPlayerOptions po;
    po.path = (dir / "missing.trec").string();
    CHECK_THROWS_WITH(RecordingPlayer(po), Catch::Contains("missing.trec"));
    RecorderOptions bad = ro;
    bad.compression = "lz4";
    CHECK_THROWS_WITH(RecorderActor(bad), Catch::Contains("compression"));
  }
}
