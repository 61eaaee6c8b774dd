#include "test_actors.hpp"

#include <tessera/runtime/harness.hpp>

#include <catch2/catch.hpp>

using namespace tessera;
using namespace tessera::test;

namespace {
/// Doubles every Blob's seq and republishes it; publishes a tick count every second.
class Doubler : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx_ = &ctx;
    out_ = ctx.advertise<msg::Blob>("out");
    ticks_ = ctx.advertise<msg::Blob>("ticks");
    ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(2), [this](const Message<msg::Blob>& m) {
      auto loan = out_.loan();
      setHeader(loan->initHeader(), ctx_->now(), "x", m->getHeader().getSeq() * 2);
      out_.publish(std::move(loan));
    });
    ctx.addTimer(
        kNanosPerSecond,
        [this] {
          auto loan = ticks_.loan();
          setHeader(loan->initHeader(), ctx_->now(), "x", ticks_.nextSeq());
          ticks_.publish(std::move(loan));
        },
        kNanosPerSecond);
  }
  void stop() override {
    auto loan = out_.loan();
    setHeader(loan->initHeader(), ctx_->now(), "final", 999);
    out_.publish(std::move(loan));
  }

 private:
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Blob> out_, ticks_;
};
}  // namespace

TEST_CASE("the harness steps one actor deterministically and captures what it publishes",
          "[harness]") {
  ActorHarness h(std::make_unique<Doubler>());
  for (std::uint64_t i = 1; i <= 5; ++i) {
    h.push<msg::Blob>("in", [&](msg::Blob::Builder b) { setHeader(b.initHeader(), 0, "in", i); });
  }
  CHECK(h.publishedCount("out") == 0);  // queued, not handled yet (beyond what back-pressure ran)
  h.runUntilIdle();
  auto out = h.published<msg::Blob>("out");
  REQUIRE(out.size() == 5);
  for (std::size_t i = 0; i < 5; ++i) CHECK(out[i]->getHeader().getSeq() == 2 * (i + 1));

  h.advance(secondsToNanos(3.5));
  auto ticks = h.published<msg::Blob>("ticks");
  REQUIRE(ticks.size() == 3);
  CHECK(ticks[0]->getHeader().getStampNs() == secondsToNanos(1.0));
  CHECK(ticks[2]->getHeader().getStampNs() == secondsToNanos(3.0));
  CHECK(h.now() == secondsToNanos(3.5));

  h.stop();
  out = h.published<msg::Blob>("out");
  CHECK(out.back()->getHeader().getSeq() == 999);
}

TEST_CASE("the harness rejects topics the actor does not use", "[harness]") {
  ActorHarness h(std::make_unique<Doubler>());
  CHECK_THROWS_WITH(h.push<msg::Blob>("nope", [](msg::Blob::Builder) {}), Catch::Contains("nope"));
  CHECK_THROWS_WITH(h.push<msg::LaserScan>("in", [](msg::LaserScan::Builder) {}),
                    Catch::Contains("LaserScan"));
  CHECK_THROWS_AS(h.published<msg::Blob>("in"), std::invalid_argument);
}
