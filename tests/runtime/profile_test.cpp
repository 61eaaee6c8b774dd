#include "test_actors.hpp"

#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/registry.hpp>

#include <catch2/catch.hpp>

using namespace tessera;

namespace {
struct SourceOptions {
  int count = 3;
  double period_s = 0.1;
  std::string label = "x";
  template <class V>
  void visit(V& v) {
    v("count", count, "messages to publish");
    v("period_s", period_s, "seconds between messages");
    v("label", label, "a label");
  }
};
struct SinkOptions {
  int capacity = 4;
  double period_s = 1.0;
  template <class V>
  void visit(V& v) {
    v("capacity", capacity, "mailbox capacity");
    v("period_s", period_s, "unused");
  }
};
struct TestSource : test::CountingSource {
  explicit TestSource(const SourceOptions& o)
      : CountingSource(o.count, secondsToNanos(o.period_s)), options(o) {}
  SourceOptions options;
};
struct TestSink : test::Recorder {
  explicit TestSink(const SinkOptions& o) : Recorder(MailboxPolicy::reliable(o.capacity)) {}
};
TESSERA_REGISTER_ACTOR("test_source", TestSource, SourceOptions, "test source");
TESSERA_REGISTER_ACTOR("test_sink", TestSink, SinkOptions, "test sink");

const char* kGood = R"(name: demo
clock: sim
actors:
  src:
    type: test_source
    params:
      count: 5
  sink:
    type: test_sink
    remap: {in: out}
)";
}  // namespace

TEST_CASE("a valid profile builds and runs", "[profile]") {
  auto p = parseProfile(kGood, "demo.yaml");
  REQUIRE(p.actors.size() == 2);
  CHECK(p.actors[0].line == 4);
  RuntimeOptions o;
  o.show_progress = false;
  auto rt = buildRuntime(p, o);
  auto report = rt->run();
  CHECK(report.actors[1].messages_in == 5);
}

TEST_CASE("an actor's namespace prefixes the topics it does not remap", "[profile]") {
  // Two robots' pipelines side by side: r1's source feeds r1's sink, r2's source r2's sink.
  const char* two = R"(actors:
  src1: {type: test_source, namespace: r1, params: {count: 3}}
  src2: {type: test_source, namespace: r2, params: {count: 5}}
  sink1: {type: test_sink, namespace: r1, remap: {in: r1/out}}
  sink2: {type: test_sink, namespace: fleet/r2, remap: {in: r2/out}}
)";
  auto p = parseProfile(two, "two.yaml");
  CHECK(p.actors[0].topic_namespace == "r1");
  RuntimeOptions o;
  o.show_progress = false;
  auto rt = buildRuntime(p, o);
  CHECK(rt->globalTopic("src1", "out") == "r1/out");
  CHECK(rt->globalTopic("src2", "out") == "r2/out");
  CHECK(rt->globalTopic("sink2", "in") == "r2/out");  // a remap is global as written
  auto report = rt->run();
  CHECK(report.actors[2].messages_in == 3);
  CHECK(report.actors[3].messages_in == 5);
  for (const char* bad : {"/r1", "r1/", "r 1", "a//b", "''"}) {
    INFO(bad);
    CHECK_THROWS_WITH(
        parseProfile(
            std::string("actors:\n  a:\n    type: test_source\n    namespace: ") + bad + "\n",
            "p.yaml"),
        Catch::Contains("p.yaml:4") && Catch::Contains("namespace"));
  }
}

TEST_CASE("overrides given with --set change actor parameters and top-level keys", "[profile]") {
  auto p = parseProfile(kGood, "demo.yaml", {"src.count=7", "label=hello", "max_duration_s=2.5"});
  CHECK(p.max_duration_s == 2.5);
  auto o = loadOptions<SourceOptions>(p.actors[0].params);
  CHECK(o.count == 7);
  CHECK(o.label == "hello");
  CHECK_THROWS_WITH(parseProfile(kGood, "demo.yaml", {"period_s=1"}),
                    Catch::Contains("several actors") && Catch::Contains("src.period_s"));
  CHECK_THROWS_WITH(parseProfile(kGood, "demo.yaml", {"nosuch=1"}), Catch::Contains("nosuch"));
  CHECK_THROWS_WITH(parseProfile(kGood, "demo.yaml", {"ghost.count=1"}), Catch::Contains("ghost"));
  CHECK_THROWS_WITH(parseProfile(kGood, "demo.yaml", {"count"}), Catch::Contains("KEY=VALUE"));
}

TEST_CASE("profile errors name the file, the line and the key", "[profile]") {
  RuntimeOptions o;
  o.show_progress = false;
  SECTION("unknown top-level key") {
    CHECK_THROWS_WITH(parseProfile("name: x\nactorz: {}\n", "p.yaml"),
                      Catch::Contains("p.yaml:2") && Catch::Contains("actorz"));
  }
  SECTION("unknown actor field") {
    CHECK_THROWS_WITH(
        parseProfile("actors:\n  a:\n    type: test_source\n    parms: {}\n", "p.yaml"),
        Catch::Contains("p.yaml:4") && Catch::Contains("parms"));
  }
  SECTION("unknown actor type") {
    CHECK_THROWS_WITH(
        parseProfile("actors:\n  a:\n    type: nope\n", "p.yaml"),
        Catch::Contains("p.yaml:3") && Catch::Contains("nope") && Catch::Contains("test_source"));
  }
  SECTION("unknown parameter") {
    auto p = parseProfile("actors:\n  a:\n    type: test_source\n    params:\n      cuont: 3\n",
                          "p.yaml");
    CHECK_THROWS_WITH(buildRuntime(p, o), Catch::Contains("p.yaml") && Catch::Contains("line 5") &&
                                              Catch::Contains("cuont") && Catch::Contains("count"));
  }
  SECTION("wrong type") {
    auto p = parseProfile("actors:\n  a:\n    type: test_source\n    params:\n      count: many\n",
                          "p.yaml");
    CHECK_THROWS_WITH(buildRuntime(p, o), Catch::Contains("count") &&
                                              Catch::Contains("whole number") &&
                                              Catch::Contains("many"));
    auto q = parseProfile("actors:\n  a:\n    type: test_source\n    params:\n      count: 2.5\n",
                          "p.yaml");
    CHECK_THROWS_WITH(buildRuntime(q, o), Catch::Contains("2.5"));
    auto r = parseProfile(
        "actors:\n  a:\n    type: test_source\n    params:\n      period_s: .nan\n", "p.yaml");
    CHECK_THROWS_WITH(buildRuntime(r, o), Catch::Contains("finite"));
  }
  SECTION("a topic nobody publishes") {
    auto p = parseProfile("actors:\n  s:\n    type: test_sink\n", "p.yaml");
    CHECK_THROWS_WITH(buildRuntime(p, o), Catch::Contains("p.yaml") && Catch::Contains("'in'"));
  }
  SECTION("bad clock and YAML syntax") {
    CHECK_THROWS_WITH(parseProfile("clock: moon\nactors: {a: {type: test_source}}\n", "p.yaml"),
                      Catch::Contains("moon") && Catch::Contains("paced"));
    // A paced clock needs its rate.
    RuntimeOptions quiet;
    quiet.show_progress = false;
    CHECK_THROWS_WITH(
        buildRuntime(parseProfile("clock: paced\nactors: {a: {type: test_source}}\n", "p.yaml"),
                     quiet),
        Catch::Contains("p.yaml") && Catch::Contains("sim_rate > 0"));
    CHECK_THROWS_WITH(parseProfile("actors: [\n", "p.yaml"), Catch::Contains("syntax"));
    CHECK_THROWS_WITH(parseProfile("", "p.yaml"), Catch::Contains("mapping"));
  }
  SECTION("missing file") {
    CHECK_THROWS_WITH(loadProfile("/nonexistent/x.yaml"), Catch::Contains("/nonexistent/x.yaml"));
    CHECK_THROWS_WITH(resolveProfilePath("nope", {"/tmp"}), Catch::Contains("/tmp/nope.yaml"));
  }
}

TEST_CASE("topics listed under external: need no publisher inside and must be used by an actor",
          "[profile]") {
  RuntimeOptions o;
  o.show_progress = false;
  const std::string sink_only = "actors:\n  s:\n    type: test_sink\n";
  // Published from outside: the sink's topic needs no publisher in the profile.
  auto p = parseProfile("external: {inputs: [in]}\n" + sink_only, "p.yaml");
  CHECK(p.external_inputs == std::vector<std::string>{"in"});
  CHECK_NOTHROW(buildRuntime(p, o));
  auto q = parseProfile("external: {outputs: [out]}\n" + std::string(kGood), "q.yaml");
  CHECK(q.external_outputs == std::vector<std::string>{"out"});
  CHECK_NOTHROW(buildRuntime(q, o));
  // A listed topic nobody uses is a typo, not a wish.
  auto r = parseProfile("external: {inputs: [in, goal]}\n" + sink_only, "r.yaml");
  CHECK_THROWS_WITH(buildRuntime(r, o), Catch::Contains("r.yaml") &&
                                            Catch::Contains("external.inputs") &&
                                            Catch::Contains("no actor subscribes to topic 'goal'"));
  auto s = parseProfile("external: {inputs: [in], outputs: [in]}\n" + sink_only, "s.yaml");
  CHECK_THROWS_WITH(buildRuntime(s, o), Catch::Contains("external.outputs") &&
                                            Catch::Contains("no actor publishes topic 'in'"));
  CHECK_THROWS_WITH(parseProfile("external: [in]\n" + sink_only, "t.yaml"),
                    Catch::Contains("t.yaml:1") && Catch::Contains("expected a mapping"));
  CHECK_THROWS_WITH(parseProfile("external: {inputs: in}\n" + sink_only, "t.yaml"),
                    Catch::Contains("external.inputs: expected a list of topic names"));
  CHECK_THROWS_WITH(parseProfile("external: {input: [in]}\n" + sink_only, "t.yaml"),
                    Catch::Contains("unknown key 'input'") && Catch::Contains("inputs, outputs"));
  CHECK_THROWS_WITH(parseProfile("external: {inputs: ['']}\n" + sink_only, "t.yaml"),
                    Catch::Contains("empty topic name"));
}
