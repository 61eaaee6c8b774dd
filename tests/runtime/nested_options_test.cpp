// Nested option groups (options.hpp): an actor's options holding a core's struct read from a
// YAML sub-mapping, unknown and moved keys rejected by path, --set reaching nested keys, and
// the dotted names `tessera actors` lists.
#include "test_actors.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/registry.hpp>

#include <catch2/catch.hpp>

using namespace tessera;

namespace {
// Stands for a core's options: plain C++, its visit() a template over any visitor.
struct InnerCore {
  struct Noise {
    double sigma = 0.1;
    template <class V>
    void visit(V& v) {
      v("sigma", sigma, "noise");
    }
  };
  int count = 3;
  Noise noise;
  template <class V>
  void visit(V& v) {
    v("count", count, "messages to publish");
    v("noise", noise, "noise model");
  }
};
struct NestedOptions {
  InnerCore core;
  double period_s = 0.1;
  template <class V>
  void visit(V& v) {
    v("core", core, "the core");
    v("period_s", period_s, "seconds between messages");
  }
  static constexpr RenamedKey kRenamedKeys[] = {{"count", "core.count"},
                                                {"sigma", "core.noise.sigma"}};
};
struct NestedSource : test::CountingSource {
  explicit NestedSource(const NestedOptions& o)
      : CountingSource(o.core.count, secondsToNanos(o.period_s)) {}
};
TESSERA_REGISTER_ACTOR("test_nested_source", NestedSource, NestedOptions, "nested options");

Profile profile(const std::string& params, const std::vector<std::string>& sets = {}) {
  return parseProfile("actors:\n  a:\n    type: test_nested_source\n    params:\n" + params,
                      "p.yaml", sets);
}
NestedOptions load(const Profile& p) {
  return loadOptions<NestedOptions>(p.actors.at(0).params);
}
}  // namespace

TEST_CASE("a nested option group reads its YAML sub-mapping", "[options]") {
  const auto o = load(profile("      core:\n        count: 7\n        noise: {sigma: 0.5}\n"));
  CHECK(o.core.count == 7);
  CHECK(o.core.noise.sigma == 0.5);
  CHECK(o.period_s == 0.1);
  const auto d = load(profile("      period_s: 2\n"));  // groups keep their defaults
  CHECK(d.core.count == 3);
  CHECK(d.core.noise.sigma == 0.1);
}

TEST_CASE("unknown keys inside a group are rejected with their path and line", "[options]") {
  CHECK_THROWS_WITH(load(profile("      core:\n        cuont: 7\n")),
                    Catch::Contains("p.yaml") && Catch::Contains("actors.a.params.core.cuont") &&
                        Catch::Contains("line 6") && Catch::Contains("count, noise"));
  CHECK_THROWS_WITH(load(profile("      core:\n        noise: {sigmaa: 1}\n")),
                    Catch::Contains("core.noise.sigmaa"));
  CHECK_THROWS_WITH(load(profile("      core: 3\n")),
                    Catch::Contains("params.core") && Catch::Contains("mapping"));
}

TEST_CASE("an old flat key fails with an error naming its new key", "[options]") {
  CHECK_THROWS_WITH(load(profile("      count: 7\n")),
                    Catch::Contains("actors.a.params.count, line 5: moved to core.count"));
  CHECK_THROWS_WITH(load(profile("      sigma: 1\n")),
                    Catch::Contains("moved to core.noise.sigma"));
  CHECK_THROWS_WITH(profile("", {"a.count=7"}), Catch::Contains("moved to a.core.count"));
  CHECK_THROWS_WITH(profile("", {"count=7"}), Catch::Contains("moved to a.core.count"));
}

TEST_CASE("a --set of a nested key reaches it, with or without the actor's name", "[options]") {
  CHECK(load(profile("      period_s: 1\n", {"a.core.count=9"})).core.count == 9);
  CHECK(load(profile("      period_s: 1\n", {"a.core.noise.sigma=2"})).core.noise.sigma == 2);
  CHECK(load(profile("      core: {count: 1}\n", {"core.count=4"})).core.count == 4);
  const auto both = load(profile("      core: {count: 1}\n", {"core.noise.sigma=3"}));
  CHECK(both.core.count == 1);
  CHECK(both.core.noise.sigma == 3);
}

TEST_CASE("described options list nested keys by their dotted path", "[options]") {
  const auto rows = describeOptions<NestedOptions>();
  REQUIRE(rows.size() == 3);
  CHECK(rows[0] == std::array<std::string, 3>{"core.count", "3", "messages to publish"});
  CHECK(rows[1] == std::array<std::string, 3>{"core.noise.sigma", "0.1", "noise"});
  CHECK(rows[2][0] == "period_s");
  const auto* entry = ActorRegistry::instance().find("test_nested_source");
  REQUIRE(entry != nullptr);
  CHECK(entry->renamed.size() == 2);
}

namespace {
// An enum option as a core declares it: the name table beside the enum, found by ADL.
enum class Shape { kRound, kSquare };
constexpr std::array<std::pair<const char*, Shape>, 2> optionNames(Shape) {
  return {{{"round", Shape::kRound}, {"square", Shape::kSquare}}};
}
struct EnumOptions {
  Shape shape = Shape::kSquare;
  template <class V>
  void visit(V& v) {
    v("shape", shape, "outline");
  }
};
EnumOptions loadEnum(const std::string& params) {
  const Profile p =
      parseProfile("actors:\n  a:\n    type: test_nested_source\n    params:\n" + params, "p.yaml");
  return loadOptions<EnumOptions>(p.actors.at(0).params);
}
}  // namespace

TEST_CASE("an enum option is read by name and a wrong name lists the accepted ones", "[options]") {
  CHECK(loadEnum("      shape: round\n").shape == Shape::kRound);
  CHECK(loadEnum("      {}\n").shape == Shape::kSquare);
  CHECK_THROWS_WITH(loadEnum("      shape: oval\n"),
                    Catch::Contains("actors.a.params.shape, line 5") &&
                        Catch::Contains("expected one of round | square, got 'oval'"));
  CHECK_THROWS_WITH(loadEnum("      shape: [1]\n"), Catch::Contains("expected a string"));
  const auto rows = describeOptions<EnumOptions>();
  REQUIRE(rows.size() == 1);
  CHECK(rows[0] == std::array<std::string, 3>{"shape", "square", "outline (round | square)"});
}
