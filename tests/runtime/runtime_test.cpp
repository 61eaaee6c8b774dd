#include "test_actors.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <string>
#include <thread>

using namespace tessera;
using namespace tessera::test;

namespace {
RuntimeOptions manualOptions() {
  RuntimeOptions o;
  o.manual = true;
  o.show_progress = false;
  return o;
}
RuntimeOptions threadedOptions() {
  RuntimeOptions o;
  o.show_progress = false;
  o.threads = 2;
  return o;
}
void publishBlobs(Publisher<msg::Blob>& pub, int n) {
  for (int i = 0; i < n; ++i) {
    auto loan = pub.loan();
    setHeader(loan->initHeader(), 0, "t", pub.nextSeq());
    pub.publish(std::move(loan));
  }
}
}  // namespace

TEST_CASE("keep_latest keeps the newest n messages and counts the drops", "[runtime]") {
  Runtime rt(manualOptions());
  auto pub = rt.externalPublisher<msg::Blob>("in");
  auto& rec = static_cast<Recorder&>(
      rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::keepLatest(3))));
  rt.configure();
  rt.start();
  publishBlobs(pub, 10);
  CHECK(rt.runUntilIdle() == 3);
  CHECK(rec.seqs == std::vector<std::uint64_t>{7, 8, 9});
  rt.stop();
  CHECK(rt.report().actors[0].drops == 7);
  CHECK(rt.report().actors[0].messages_in == 3);
}

TEST_CASE("reliable mailboxes never drop, even when the publisher outruns the consumer",
          "[runtime]") {
  SECTION("manual stepping: a full mailbox makes the publisher run the consumer") {
    Runtime rt(manualOptions());
    auto pub = rt.externalPublisher<msg::Blob>("in");
    auto& rec = static_cast<Recorder&>(
        rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(4))));
    rt.configure();
    rt.start();
    publishBlobs(pub, 100);
    rt.runUntilIdle();
    REQUIRE(rec.seqs.size() == 100);
    for (std::uint64_t i = 0; i < 100; ++i) CHECK(rec.seqs[i] == i);
    CHECK(rt.report().actors[0].drops == 0);
    CHECK(rt.report().actors[0].max_queue_depth <= 4);
  }
  SECTION("threaded: a slow consumer back-pressures a fast source") {
    Runtime rt(threadedOptions());
    rt.add("src", std::make_unique<CountingSource>(300, 1));
    auto& rec = static_cast<Recorder&>(rt.add(
        "rec",
        std::make_unique<Recorder>(MailboxPolicy::reliable(2), std::chrono::microseconds(50)),
        {{"in", "out"}}));
    auto report = rt.run();
    REQUIRE(rec.seqs.size() == 300);
    for (std::uint64_t i = 0; i < 300; ++i) CHECK(rec.seqs[i] == i);
    CHECK(report.stop_reason == "all inputs finished");
  }
}

TEST_CASE(
    "the report gives each subscription's policy, handled and evicted messages and the inbox wait",
    "[runtime]") {
  SECTION("manual stepping: queued messages waited, keep_latest evictions counted") {
    Runtime rt(manualOptions());
    auto pub = rt.externalPublisher<msg::Blob>("in");
    rt.add("latest", std::make_unique<Recorder>(MailboxPolicy::keepLatest(2)));
    rt.add("all", std::make_unique<Recorder>(MailboxPolicy::reliable(64)));
    rt.configure();
    rt.start();
    publishBlobs(pub, 10);
    std::this_thread::sleep_for(std::chrono::milliseconds(3));  // they wait in the inboxes
    rt.runUntilIdle();
    rt.stop();
    const auto report = rt.report();
    REQUIRE(report.actors.size() == 2);
    const auto& latest = report.actors[0];
    REQUIRE(latest.subscriptions.size() == 1);
    CHECK(latest.subscriptions[0].topic == "in");
    CHECK_FALSE(latest.subscriptions[0].reliable);
    CHECK(latest.subscriptions[0].handled == 2);
    CHECK(latest.subscriptions[0].drops == 8);
    const auto& all = report.actors[1];
    CHECK(all.subscriptions[0].reliable);
    CHECK(all.subscriptions[0].handled == 10);
    CHECK(all.subscriptions[0].drops == 0);
    CHECK(all.queue_wait_p50_us >= 3000);  // >= the 3 ms they sat queued
    CHECK(all.queue_wait_p99_us >= all.queue_wait_p50_us);
  }
  SECTION("threaded: a slow consumer's messages wait about one handler time each") {
    Runtime rt(threadedOptions());
    rt.add("src", std::make_unique<CountingSource>(200, 1));
    rt.add("rec",
           std::make_unique<Recorder>(MailboxPolicy::reliable(2), std::chrono::microseconds(200)),
           {{"in", "out"}});
    const auto report = rt.run();
    const auto& rec = report.actors[1];
    CHECK(rec.subscriptions[0].handled == 200);
    CHECK(rec.queue_wait_p99_us > 0);
    CHECK(rec.queue_wait_p99_us < 1e6);  // bounded by the mailbox: 2 messages of 200 us
  }
}

TEST_CASE("a paced clock does not wait for slow actors: keep_latest evicts, reliable loses nothing",
          "[runtime]") {
  auto o = threadedOptions();
  o.clock = ClockKind::kPaced;
  o.sim_rate = 2.0;  // 2 simulated ms per wall ms: a message every 0.5 ms of wall time
  Runtime rt(o);
  rt.add("src", std::make_unique<CountingSource>(400, secondsToNanos(0.001)));
  auto& latest = static_cast<Recorder&>(rt.add(
      "latest",
      std::make_unique<Recorder>(MailboxPolicy::keepLatest(1), std::chrono::microseconds(10000)),
      {{"in", "out"}}));
  auto& all = static_cast<Recorder&>(
      rt.add("all", std::make_unique<Recorder>(MailboxPolicy::reliable(8)), {{"in", "out"}}));
  const auto report = rt.run();
  CHECK(report.stop_reason == "all inputs finished");
  // The source ran on time (0.2 s of wall for 0.4 s of data), the slow actor saw a fraction.
  CHECK(report.wall_s < 2.0);
  CHECK(all.seqs.size() == 400);
  CHECK(latest.seqs.size() < 200);  // about 1 in 20 when the machine is idle
  CHECK(report.actors[1].drops + latest.seqs.size() == 400);
  CHECK(report.actors[1].subscriptions[0].drops == report.actors[1].drops);
  // Stamps follow the paced clock: 1 ms apart in simulated time (more where the source's
  // timer fell behind and skipped ahead), never backwards.
  for (std::size_t i = 1; i < all.stamps.size(); ++i) CHECK(all.stamps[i] > all.stamps[i - 1]);
  CHECK(all.stamps.back() - all.stamps.front() >= secondsToNanos(0.399) * 0.9);
}

TEST_CASE("simulated time advances timer to timer and is deterministic", "[runtime]") {
  auto once = [] {
    Runtime rt(threadedOptions());
    rt.add("src", std::make_unique<CountingSource>(50, secondsToNanos(0.1)));
    auto& rec = static_cast<Recorder&>(
        rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1)), {{"in", "out"}}));
    auto report = rt.run();
    return std::make_pair(rec.stamps, report);
  };
  auto [a, report] = once();
  auto [b, report2] = once();
  REQUIRE(a.size() == 50);  // keep_latest(1) loses nothing: time waits for the consumer
  CHECK(a == b);
  CHECK(a.front() == 0);
  CHECK(a.back() == secondsToNanos(4.9));
  CHECK(report.sim_duration_s == Approx(4.9));
  CHECK(report.actors[1].drops == 0);
}

namespace {
/// Answers every Blob on "in" with one on "out" tagged with its name, after a random wall-clock
/// pause of up to 2 ms: two of them answering the same tick race each other on two threads.
class RandomDelayRelay : public Actor {
 public:
  explicit RandomDelayRelay(std::string tag) : tag_(std::move(tag)), rng_(std::random_device{}()) {}
  void configure(ActorContext& ctx) override {
    out_ = ctx.advertise<msg::Blob>("out");
    ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(8), [this](const Message<msg::Blob>& m) {
      std::this_thread::sleep_for(
          std::chrono::microseconds(std::uniform_int_distribution<int>(0, 2000)(rng_)));
      auto loan = out_.loan(8);
      setHeader(loan->initHeader(), m->getHeader().getStampNs(), tag_, out_.nextSeq());
      loan->initPayload(8);
      out_.publish(std::move(loan));
    });
  }

 private:
  std::string tag_;
  std::mt19937 rng_;
  Publisher<msg::Blob> out_;
};

/// Writes down the tag of every answer on "a" and "b", in the order it handles them.
class AnswerOrder : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    for (const char* in : {"a", "b"})
      ctx.subscribe<msg::Blob>(in, MailboxPolicy::reliable(8), [this](const Message<msg::Blob>& m) {
        order += m->getHeader().getFrameId().cStr();
      });
  }
  std::string order;
};
}  // namespace

TEST_CASE("a simulated-clock run repeats exactly by default when actors answer within an instant",
          "[runtime]") {
  // Each tick reaches two relays whose answers meet in one actor. Time waits for all of them,
  // so every answer lands in the same instant; what can differ is the order they arrive in,
  // which with two executor threads would follow the relays' random pauses.
  auto once = [] {
    RuntimeOptions o;
    o.show_progress = false;  // threads left at 0: the default under test
    Runtime rt(o);
    rt.add("src", std::make_unique<CountingSource>(30, secondsToNanos(0.1)), {{"out", "tick"}});
    rt.add("p", std::make_unique<RandomDelayRelay>("p"), {{"in", "tick"}, {"out", "pa"}});
    rt.add("q", std::make_unique<RandomDelayRelay>("q"), {{"in", "tick"}, {"out", "qa"}});
    auto& seen = static_cast<AnswerOrder&>(
        rt.add("seen", std::make_unique<AnswerOrder>(), {{"a", "pa"}, {"b", "qa"}}));
    rt.run();
    return seen.order;
  };
  const std::string first = once();
  REQUIRE(first.size() == 60);
  for (int run = 0; run < 2; ++run) CHECK(once() == first);
}

TEST_CASE("max_sim_duration ends a run that has no finite source", "[runtime]") {
  auto o = threadedOptions();
  o.max_sim_duration = secondsToNanos(2.0);
  Runtime rt(o);
  rt.add("src", std::make_unique<CountingSource>(1000000, secondsToNanos(0.5)));
  auto& rec = static_cast<Recorder&>(
      rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(8)), {{"in", "out"}}));
  auto report = rt.run();
  CHECK(rec.seqs.size() == 5);  // t = 0, 0.5, 1.0, 1.5, 2.0
  CHECK(report.stop_reason == "reached max_duration_s");
}

TEST_CASE("the report counts each topic's messages and bytes published in this process",
          "[runtime]") {
  Runtime rt(threadedOptions());
  rt.add("small", std::make_unique<CountingSource>(4, 1'000'000, 8));
  rt.add("large", std::make_unique<CountingSource>(3, 1'000'000, 100'000), {{"out", "big"}});
  rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(8)), {{"in", "out"}});
  auto report = rt.run();
  REQUIRE(report.topics.size() == 2);
  CHECK(report.topics[0].name == "big");
  CHECK(report.topics[0].messages == 3);
  // Each message holds its 100 000-byte payload, rounded up to words, and a small header.
  CHECK(report.topics[0].bytes >= 3 * 100'000);
  CHECK(report.topics[0].bytes < 3 * 100'500);
  CHECK(report.topics[1].name == "out");
  CHECK(report.topics[1].messages == 4);
  CHECK(report.topics[1].bytes > 4 * 8);
  CHECK(report.topics[1].bytes < 4 * 500);
}

TEST_CASE("stopping drains every reliable mailbox before downstream actors stop", "[runtime]") {
  auto o = threadedOptions();
  o.clock = ClockKind::kWall;
  Runtime rt(o);
  rt.add("src", std::make_unique<CountingSource>(200, 100'000));  // 10 kHz wall-clock source
  auto& rec = static_cast<Recorder&>(rt.add(
      "rec",
      std::make_unique<Recorder>(MailboxPolicy::reliable(1000), std::chrono::microseconds(200)),
      {{"in", "out"}}));
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    rt.requestStop();
  });
  auto report = rt.run();
  stopper.join();
  CHECK(report.interrupted);
  // Whatever the source published before the stop was handled, and before rec.stop() ran.
  CHECK(rec.seen_at_stop == rec.seqs.size());
  CHECK(report.actors[1].messages_in == report.actors[0].messages_out);
  CHECK(report.actors[1].drops == 0);
}

TEST_CASE("any number of SIGHUPs stop the run once and cleanly", "[runtime]") {
  // A worker receives the parent-death signal once per thread of its dying launcher: the
  // repeats must not count as a second Ctrl-C, which exits without writing outputs.
  struct sigaction saved_hup {
  }, saved_int{}, saved_term{};
  sigaction(SIGHUP, nullptr, &saved_hup);
  sigaction(SIGINT, nullptr, &saved_int);
  sigaction(SIGTERM, nullptr, &saved_term);
  auto o = threadedOptions();
  o.clock = ClockKind::kWall;
  Runtime rt(o);
  rt.add("src", std::make_unique<CountingSource>(1'000'000, 1'000'000));  // 1 kHz for 1000 s
  rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(1000)), {{"in", "out"}});
  rt.installSignalHandlers();
  std::thread hangups([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    for (int i = 0; i < 4; ++i) ::kill(::getpid(), SIGHUP);
  });
  const auto report = rt.run();
  hangups.join();
  ::kill(::getpid(), SIGHUP);  // after the run: still handled, still harmless
  sigaction(SIGHUP, &saved_hup, nullptr);
  sigaction(SIGINT, &saved_int, nullptr);
  sigaction(SIGTERM, &saved_term, nullptr);
  CHECK(report.interrupted);
  CHECK(report.actors[1].messages_in == report.actors[0].messages_out);
  CHECK(report.actors[0].messages_out < 100'000);
}

TEST_CASE("fan-out shares one message: every subscriber sees the same bytes", "[runtime]") {
  Runtime rt(manualOptions());
  auto pub = rt.externalPublisher<msg::Blob>("in");
  std::vector<Recorder*> recs;
  for (int i = 0; i < 4; ++i) {
    recs.push_back(&static_cast<Recorder&>(rt.add(
        "rec" + std::to_string(i), std::make_unique<Recorder>(MailboxPolicy::keepLatest(4)))));
  }
  rt.configure();
  rt.start();
  auto loan = pub.loan(1 << 20);
  loan->initPayload(1 << 20);
  auto sealed = std::move(loan).seal();
  const void* published_at = sealed->address();
  pub.publish(Message<msg::Blob>(sealed));
  rt.runUntilIdle();
  for (auto* r : recs) {
    REQUIRE(r->addresses.size() == 1);
    CHECK(r->addresses[0] == published_at);
  }
}

TEST_CASE("wiring errors are reported at configure time", "[runtime]") {
  SECTION("a subscribed topic that nobody publishes") {
    Runtime rt(manualOptions());
    rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1)));
    CHECK_THROWS_WITH(rt.configure(),
                      Catch::Contains("'in'") && Catch::Contains("no actor publishes"));
  }
  SECTION("an observer's optional subscription needs no publisher, a plain one beside it does") {
    Runtime rt(manualOptions());
    rt.add("viewer", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1).asOptional()));
    CHECK_NOTHROW(rt.configure());
    Runtime rt2(manualOptions());
    rt2.add("viewer", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1).asOptional()));
    rt2.add("rec", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1)));
    CHECK_THROWS_WITH(rt2.configure(),
                      Catch::Contains("no actor publishes") && Catch::Contains("rec"));
  }
  SECTION("two message types on one topic") {
    Runtime rt(manualOptions());
    rt.externalPublisher<msg::LaserScan>("in");
    rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::keepLatest(1)));
    CHECK_THROWS_WITH(rt.configure(), Catch::Contains("Blob") && Catch::Contains("LaserScan"));
  }
  SECTION("a remap of a topic the actor does not use") {
    Runtime rt(manualOptions());
    rt.add("src", std::make_unique<CountingSource>(1, 1), {{"outt", "x"}});
    CHECK_THROWS_WITH(rt.configure(), Catch::Contains("outt") && Catch::Contains("out"));
  }
  SECTION("duplicate actor names") {
    Runtime rt(manualOptions());
    rt.add("a", std::make_unique<CountingSource>(1, 1));
    CHECK_THROWS_AS(rt.add("a", std::make_unique<CountingSource>(1, 1)), ConfigError);
  }
}

TEST_CASE("a handler that throws stops the run with a reason instead of crashing", "[runtime]") {
  struct Thrower : Actor {
    void configure(ActorContext& ctx) override {
      ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(4),
                               [](const Message<msg::Blob>&) { throw std::runtime_error("boom"); });
    }
  };
  Runtime rt(threadedOptions());
  rt.add("src", std::make_unique<CountingSource>(1000, secondsToNanos(0.01)));
  rt.add("bad", std::make_unique<Thrower>(), {{"in", "out"}});
  auto report = rt.run();
  CHECK(report.interrupted);
  CHECK_THAT(report.stop_reason, Catch::Contains("bad") && Catch::Contains("boom"));
}

TEST_CASE("an actor that throws in stop() does not keep the others from stopping", "[runtime]") {
  struct BadStop : Actor {
    void configure(ActorContext& ctx) override {
      ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(4), [](const Message<msg::Blob>&) {});
    }
    void stop() override { throw std::runtime_error("disk full"); }
  };
  Runtime rt(threadedOptions());
  rt.add("src", std::make_unique<CountingSource>(3, secondsToNanos(0.1)));
  rt.add("bad", std::make_unique<BadStop>(), {{"in", "out"}});
  auto& rec = static_cast<Recorder&>(
      rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(4)), {{"in", "out"}}));
  auto report = rt.run();
  CHECK(rec.seen_at_stop == 3);
  CHECK_THAT(report.stop_reason, Catch::Contains("disk full") && Catch::Contains("bad"));
}

namespace {
/// Publishes at irregular given times by chaining one-shot callAt timers, like a dataset player.
class IrregularSource : public Actor {
 public:
  explicit IrregularSource(std::vector<double> times_s) : times_(std::move(times_s)) {}
  void configure(ActorContext& ctx) override {
    ctx_ = &ctx;
    out_ = ctx.advertise<msg::Blob>("out");
    ctx.declareFiniteSource();
    ctx.callAt(secondsToNanos(times_.front()), [this] { emit(); });
  }
  void emit() {
    auto loan = out_.loan();
    setHeader(loan->initHeader(), ctx_->now(), "src", out_.nextSeq());
    out_.publish(std::move(loan));
    if (++next_ == times_.size()) {
      ctx_->finished();
      return;
    }
    ctx_->callAt(secondsToNanos(times_[next_]), [this] { emit(); });
  }

 private:
  std::vector<double> times_;
  std::size_t next_ = 0;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Blob> out_;
};
}  // namespace

TEST_CASE("callAt timers fire once at their time and can chain from inside a callback",
          "[runtime]") {
  const std::vector<double> times = {0.25, 0.5, 0.5, 3.0, 10.125, 10.5};
  Runtime rt(threadedOptions());
  rt.add("src", std::make_unique<IrregularSource>(times));
  auto& rec = static_cast<Recorder&>(
      rt.add("rec", std::make_unique<Recorder>(MailboxPolicy::reliable(4)), {{"in", "out"}}));
  auto report = rt.run();
  REQUIRE(rec.stamps.size() == times.size());
  for (std::size_t i = 0; i < times.size(); ++i) CHECK(rec.stamps[i] == secondsToNanos(times[i]));
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(report.actors[0].timer_calls == times.size());
}

namespace {
/// Records the seq of every Blob on "in" and the thread that handled it. Handlers may run on
/// an executor thread while the test reads, so the records are read through waitFor().
class ThreadRecorder : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(16),
                             [this](const Message<msg::Blob>& m) {
                               {
                                 std::lock_guard lock(mutex_);
                                 seqs_.push_back(m->getHeader().getSeq());
                                 threads_.push_back(std::this_thread::get_id());
                               }
                               recorded_.notify_all();
                             });
  }
  /// The seqs and threads once `n` messages were handled (or what there is after 10 s).
  std::pair<std::vector<std::uint64_t>, std::vector<std::thread::id>> waitFor(std::size_t n) {
    std::unique_lock lock(mutex_);
    recorded_.wait_for(lock, std::chrono::seconds(10), [&] { return seqs_.size() >= n; });
    return {seqs_, threads_};
  }

 private:
  std::mutex mutex_;
  std::condition_variable recorded_;
  std::vector<std::uint64_t> seqs_;
  std::vector<std::thread::id> threads_;
};

std::shared_ptr<const MessageStorage> blobWithSeq(std::uint64_t seq) {
  Loan<msg::Blob> loan;
  setHeader(loan->initHeader(), 0, "t", seq);
  return std::move(loan).seal();
}
}  // namespace

TEST_CASE("an imported message runs at once on the receiving thread when its actor is idle",
          "[runtime]") {
  RuntimeOptions o = threadedOptions();
  o.clock = ClockKind::kWall;
  Runtime rt(o);
  auto& rec = static_cast<ThreadRecorder&>(rt.add("rec", std::make_unique<ThreadRecorder>()));
  const ImportFn deliver = rt.importTopic("in", messageTypeOf<msg::Blob>());
  rt.configure();
  rt.start();

  deliver(blobWithSeq(0), false, ImportDelivery::kRunHere);
  const auto [first_seqs, first_threads] = rec.waitFor(1);
  REQUIRE(first_seqs == std::vector<std::uint64_t>{0});
  CHECK(first_threads[0] == std::this_thread::get_id());
  // Handed straight to the handler: it never waited in the inbox.
  CHECK(rt.report().actors[0].max_queue_depth == 0);

  // Messages already queued keep their place: the next one runs after them (here, or on the
  // executor thread still busy with them).
  deliver(blobWithSeq(1), false, ImportDelivery::kDefer);
  deliver(blobWithSeq(2), false, ImportDelivery::kDefer);
  deliver(blobWithSeq(3), false, ImportDelivery::kRunHere);
  CHECK(rec.waitFor(4).first == std::vector<std::uint64_t>{0, 1, 2, 3});
  CHECK(rt.report().actors[0].messages_in == 4);
  rt.stop();
}

TEST_CASE("the thread pool's threads are named for top -H, gdb and perf", "[runtime]") {
  auto poolThreads = [] {
    int named = 0;
    for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
      std::ifstream comm(task.path() / "comm");
      std::string name;
      std::getline(comm, name);
      if (name.rfind("tessera-pool-", 0) == 0) ++named;
    }
    return named;
  };
  const int before = poolThreads();
  {
    Runtime rt(threadedOptions());
    rt.add("src", std::make_unique<CountingSource>(3, 1));
    rt.start();
    // The threads name themselves as they start: wait for both, within reason.
    for (int i = 0; i < 200 && poolThreads() < before + 2; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    CHECK(poolThreads() == before + 2);
    rt.stop();
  }
}
