// Loading an actor's options struct from its `params:` block in a profile.
//
// An options struct lists its fields once, in a visit() member, with the documentation that
// `tessera actors` prints:
//
//   struct GridMapperOptions {
//     double resolution = 0.05;  // m per cell
//     template <class V> void visit(V& v) {
//       v("resolution", resolution, "cell size [m]");
//     }
//   };
//
// loadOptions<GridMapperOptions>(params) starts from the defaults, overrides what the YAML
// gives, and rejects unknown keys and wrong types with an error naming the file, line and key.
//
// A field that is itself a struct with visit() is a nested group: `v("rbpf", rbpf, "doc")`
// reads the YAML sub-mapping `rbpf:` (unknown keys inside it are errors too), and
// `tessera actors` lists its keys as `rbpf.particles`. Core libraries write such visit()
// templates without including this header: any callable visitor works.
//
// An enum field is an option when its type has a name table found by argument-dependent lookup,
// declared beside the enum in its core header (no runtime include needed):
//
//   enum class Solver { kSgd, kCeres };
//   constexpr std::array<std::pair<const char*, Solver>, 2> optionNames(Solver) {
//     return {{{"sgd", Solver::kSgd}, {"ceres", Solver::kCeres}}};
//   }
//
// The YAML gives the name; any other value is an error listing the accepted names.
//
// An options struct whose keys moved (e.g. into a group) lists them in
//   static constexpr RenamedKey kRenamedKeys[] = {{"particles", "rbpf.particles"}, ...};
// so a profile still using an old key fails with an error naming the new one. A key may name a
// group now and a value before (`scan_graph: true` -> `scan_graph: {enabled: true}`): listed too,
// a value under it is refused naming the new key.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace YAML {
class Node;
}

namespace tessera {

/// A profile or option error: the message already names file, line and key.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// An option key that moved: a profile naming `old_key` is told to use `new_key` instead.
struct RenamedKey {
  const char* old_key;
  const char* new_key;  ///< may name several keys ("a.x and b.x") when one key became several
};

/// The parameters of one actor instance: a YAML mapping plus where it came from.
class Params {
 public:
  Params();  // empty mapping
  Params(const YAML::Node& node, std::string where);
  ~Params();
  Params(const Params&);
  Params& operator=(const Params&);

  const YAML::Node& node() const;
  /// "profile.yaml: actors.mapper.params" — prefix for errors.
  const std::string& where() const { return where_; }

  /// Reads scalar/list fields; throw ConfigError naming file:line:key on a wrong type.
  void read(const char* key, double& v) const;
  void read(const char* key, float& v) const;
  void read(const char* key, int& v) const;
  void read(const char* key, std::int64_t& v) const;
  void read(const char* key, std::uint32_t& v) const;
  void read(const char* key, std::uint64_t& v) const;
  void read(const char* key, bool& v) const;
  void read(const char* key, std::string& v) const;
  void read(const char* key, std::vector<double>& v) const;
  void read(const char* key, std::vector<std::string>& v) const;
  void read(const char* key, std::vector<std::array<double, 2>>& v) const;
  /// Rejects keys not in `known`; a key in `renamed` is rejected with its new name.
  void rejectUnknown(const std::vector<std::string>& known,
                     std::span<const RenamedKey> renamed = {}) const;
  /// Error text prefix for a key: "file:line: actors.x.params.key".
  std::string locate(const char* key) const;

  /// A sub-mapping as Params (for nested option groups). A value there instead, under a key in
  /// `renamed` (a flat key that became a group's name), is rejected with its new name.
  Params child(const char* key, std::span<const RenamedKey> renamed = {}) const;

 private:
  std::unique_ptr<YAML::Node> node_;
  std::string where_;
};

namespace detail {
/// Option structs, and nested option groups, are the types with a visit() member.
struct AnyVisitor {
  template <typename T>
  void operator()(const char*, T&, const char*) {}
};
template <typename T>
concept OptionGroup = requires(T& t, AnyVisitor& v) {
  t.visit(v);
};
/// Enums with a name table (optionNames, found by argument-dependent lookup).
template <typename T>
concept NamedEnum = std::is_enum_v<T> && requires(T t) {
  optionNames(t);
};
/// The name of an enum value in its table ("?" for a value not in it).
template <NamedEnum T>
std::string enumName(T value) {
  for (const auto& [name, v] : optionNames(value))
    if (v == value) return name;
  return "?";
}
/// "a | b | c": the accepted names, for errors and `tessera actors`.
template <NamedEnum T>
std::string enumChoices(T value) {
  std::string out;
  for (const auto& entry : optionNames(value))
    out += (out.empty() ? "" : " | ") + std::string(entry.first);
  return out;
}
}  // namespace detail

/// The keys an options struct lists as moved (kRenamedKeys), or none.
template <typename Options>
std::span<const RenamedKey> renamedKeys() {
  if constexpr (requires { Options::kRenamedKeys; }) {
    return Options::kRenamedKeys;
  } else {
    return {};
  }
}

namespace detail {
struct OptionReader {
  const Params& params;
  std::vector<std::string> known;
  std::span<const RenamedKey> renamed = {};  // the struct's moved keys (top level only)
  template <typename T>
  void operator()(const char* key, T& value, const char* /*doc*/) {
    known.emplace_back(key);
    if constexpr (OptionGroup<T>) {
      const Params group = params.child(key, renamed);
      OptionReader reader{group, {}, {}};
      value.visit(reader);
      group.rejectUnknown(reader.known);
    } else if constexpr (NamedEnum<T>) {
      std::string name = enumName(value);
      params.read(key, name);
      bool found = false;
      for (const auto& [n, v] : optionNames(value))
        if (name == n) value = v, found = true;
      if (!found)
        throw ConfigError(params.locate(key) + ": expected one of " + enumChoices(value) +
                          ", got '" + name + "'");
    } else {
      params.read(key, value);
    }
  }
};
struct OptionDescriber {
  std::vector<std::array<std::string, 3>> rows;  // key (dotted inside groups), default, doc
  std::string prefix;                            // "rbpf." while describing group rbpf
  template <typename T>
  void operator()(const char* key, T& value, const char* doc);
};
std::string describeValue(double v);
std::string describeValue(float v);
std::string describeValue(int v);
std::string describeValue(std::int64_t v);
std::string describeValue(std::uint32_t v);
std::string describeValue(std::uint64_t v);
std::string describeValue(bool v);
std::string describeValue(const std::string& v);
std::string describeValue(const std::vector<double>& v);
std::string describeValue(const std::vector<std::string>& v);
std::string describeValue(const std::vector<std::array<double, 2>>& v);
template <typename T>
void OptionDescriber::operator()(const char* key, T& value, const char* doc) {
  if constexpr (OptionGroup<T>) {
    const std::string outer = prefix;
    prefix += std::string(key) + ".";
    value.visit(*this);
    prefix = outer;
  } else if constexpr (NamedEnum<T>) {
    rows.push_back(
        {prefix + key, enumName(value), std::string(doc) + " (" + enumChoices(value) + ")"});
  } else {
    rows.push_back({prefix + key, describeValue(value), doc});
  }
}
}  // namespace detail

/// Options from params: defaults, then YAML values; unknown keys and wrong types are errors.
template <typename Options>
Options loadOptions(const Params& params) {
  Options options;
  detail::OptionReader reader{params, {}, renamedKeys<Options>()};
  options.visit(reader);
  params.rejectUnknown(reader.known, reader.renamed);
  return options;
}

/// (key, default, doc) rows of an options struct, for `tessera actors`.
template <typename Options>
std::vector<std::array<std::string, 3>> describeOptions() {
  Options options;
  detail::OptionDescriber d;
  options.visit(d);
  return d.rows;
}

}  // namespace tessera
