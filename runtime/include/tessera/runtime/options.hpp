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
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
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
  /// Rejects keys not in `known`.
  void rejectUnknown(const std::vector<std::string>& known) const;
  /// Error text prefix for a key: "file:line: actors.x.params.key".
  std::string locate(const char* key) const;

  /// A sub-mapping as Params (for nested option groups).
  Params child(const char* key) const;

 private:
  std::unique_ptr<YAML::Node> node_;
  std::string where_;
};

namespace detail {
struct OptionReader {
  const Params& params;
  std::vector<std::string> known;
  template <typename T>
  void operator()(const char* key, T& value, const char* /*doc*/) {
    known.emplace_back(key);
    params.read(key, value);
  }
};
struct OptionDescriber {
  std::vector<std::array<std::string, 3>> rows;  // key, default, doc
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
  rows.push_back({key, describeValue(value), doc});
}
}  // namespace detail

/// Options from params: defaults, then YAML values; unknown keys and wrong types are errors.
template <typename Options>
Options loadOptions(const Params& params) {
  Options options;
  detail::OptionReader reader{params, {}};
  options.visit(reader);
  params.rejectUnknown(reader.known);
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
