#include <tessera/runtime/options.hpp>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <limits>
#include <sstream>
#include <string_view>

namespace tessera {

Params::Params() : node_(std::make_unique<YAML::Node>(YAML::NodeType::Map)), where_("params") {}
Params::Params(const YAML::Node& node, std::string where)
    : node_(std::make_unique<YAML::Node>(node.IsNull() ? YAML::Node(YAML::NodeType::Map) : node)),
      where_(std::move(where)) {
  if (!node_->IsMap()) {
    throw ConfigError(
        where_ +
        (node.Mark().line >= 0 ? " (line " + std::to_string(node.Mark().line + 1) + ")" : "") +
        ": expected a mapping of key: value");
  }
}
Params::~Params() = default;
// Copies share the YAML tree (yaml-cpp nodes are references), which keeps line marks for errors.
Params::Params(const Params& o) : node_(std::make_unique<YAML::Node>(*o.node_)), where_(o.where_) {}
Params& Params::operator=(const Params& o) {
  if (this != &o) {
    node_ = std::make_unique<YAML::Node>(*o.node_);
    where_ = o.where_;
  }
  return *this;
}

const YAML::Node& Params::node() const {
  return *node_;
}

std::string Params::locate(const char* key) const {
  const YAML::Node v = (*node_)[key];
  std::string line;
  if (v && v.Mark().line >= 0) line = ", line " + std::to_string(v.Mark().line + 1);
  return where_ + "." + key + line;
}

namespace {

template <typename T>
T scalarAs(const Params& p, const char* key, const YAML::Node& v, const char* expected) {
  if (!v.IsScalar())
    throw ConfigError(p.locate(key) + ": expected " + expected + ", got a " +
                      (v.IsSequence() ? "list" : "mapping"));
  try {
    return v.as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(p.locate(key) + ": expected " + expected + ", got '" + v.Scalar() + "'");
  }
}

double finiteNumber(const Params& p, const char* key, const YAML::Node& v) {
  const double d = scalarAs<double>(p, key, v, "a number");
  if (!std::isfinite(d))
    throw ConfigError(p.locate(key) + ": expected a finite number, got '" + v.Scalar() + "'");
  return d;
}

template <typename Int>
Int integer(const Params& p, const char* key, const YAML::Node& v) {
  const std::string& text = v.IsScalar() ? v.Scalar() : std::string();
  if (text.find_first_of(".eE") != std::string::npos && text.find("0x") == std::string::npos) {
    throw ConfigError(p.locate(key) + ": expected a whole number, got '" + text + "'");
  }
  if constexpr (std::is_unsigned_v<Int>) {
    if (!text.empty() && text[0] == '-')
      throw ConfigError(p.locate(key) + ": expected a non-negative whole number, got '" + text +
                        "'");
  }
  return scalarAs<Int>(p, key, v, "a whole number");
}

}  // namespace

#define TESSERA_PARAM_READ(Type, expr)                  \
  void Params::read(const char* key, Type& out) const { \
    const YAML::Node v = (*node_)[key];                 \
    if (!v || v.IsNull()) return;                       \
    out = expr;                                         \
  }

TESSERA_PARAM_READ(double, finiteNumber(*this, key, v))
TESSERA_PARAM_READ(float, static_cast<float>(finiteNumber(*this, key, v)))
TESSERA_PARAM_READ(int, integer<int>(*this, key, v))
TESSERA_PARAM_READ(std::int64_t, integer<std::int64_t>(*this, key, v))
TESSERA_PARAM_READ(std::uint32_t, integer<std::uint32_t>(*this, key, v))
TESSERA_PARAM_READ(std::uint64_t, integer<std::uint64_t>(*this, key, v))
TESSERA_PARAM_READ(bool, scalarAs<bool>(*this, key, v, "true or false"))
TESSERA_PARAM_READ(std::string, scalarAs<std::string>(*this, key, v, "a string"))
#undef TESSERA_PARAM_READ

void Params::read(const char* key, std::vector<double>& out) const {
  const YAML::Node v = (*node_)[key];
  if (!v || v.IsNull()) return;
  if (!v.IsSequence()) throw ConfigError(locate(key) + ": expected a list of numbers");
  std::vector<double> r;
  for (const auto& e : v) r.push_back(finiteNumber(*this, key, e));
  out = std::move(r);
}

void Params::read(const char* key, std::vector<std::string>& out) const {
  const YAML::Node v = (*node_)[key];
  if (!v || v.IsNull()) return;
  if (!v.IsSequence()) throw ConfigError(locate(key) + ": expected a list of strings");
  std::vector<std::string> r;
  for (const auto& e : v) r.push_back(scalarAs<std::string>(*this, key, e, "a string"));
  out = std::move(r);
}

void Params::read(const char* key, std::vector<std::array<double, 2>>& out) const {
  const YAML::Node v = (*node_)[key];
  if (!v || v.IsNull()) return;
  if (!v.IsSequence()) throw ConfigError(locate(key) + ": expected a list of [x, y] pairs");
  std::vector<std::array<double, 2>> r;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const auto& e = v[i];
    if (!e.IsSequence() || e.size() != 2) {
      throw ConfigError(locate(key) + ": element " + std::to_string(i) + " must be a pair [x, y]");
    }
    r.push_back({finiteNumber(*this, key, e[0]), finiteNumber(*this, key, e[1])});
  }
  out = std::move(r);
}

void Params::rejectUnknown(const std::vector<std::string>& known,
                           std::span<const RenamedKey> renamed) const {
  for (const auto& kv : *node_) {
    const std::string key = kv.first.as<std::string>();
    bool ok = false;
    for (const auto& k : known) ok = ok || k == key;
    if (ok) continue;
    // Keys added by --set have no line.
    const int line = kv.first.Mark().line;
    const std::string at =
        where_ + "." + key + (line >= 0 ? ", line " + std::to_string(line + 1) : "");
    for (const auto& r : renamed) {
      if (key == r.old_key) throw ConfigError(at + ": moved to " + r.new_key);
    }
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    throw ConfigError(at + ": unknown key (known keys: " + (list.empty() ? "none" : list) + ")");
  }
}

Params Params::child(const char* key, std::span<const RenamedKey> renamed) const {
  const YAML::Node v = (*node_)[key];
  if (v && !v.IsMap() && !v.IsNull()) {
    for (const auto& r : renamed)
      if (std::string_view(key) == r.old_key)
        throw ConfigError(locate(key) + ": moved to " + r.new_key);
  }
  return Params(v ? v : YAML::Node(YAML::NodeType::Map), where_ + "." + key);
}

namespace detail {
namespace {
template <typename T>
std::string num(T v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
}  // namespace
std::string describeValue(double v) {
  return num(v);
}
std::string describeValue(float v) {
  return num(v);
}
std::string describeValue(int v) {
  return num(v);
}
std::string describeValue(std::int64_t v) {
  return num(v);
}
std::string describeValue(std::uint32_t v) {
  return num(v);
}
std::string describeValue(std::uint64_t v) {
  return num(v);
}
std::string describeValue(bool v) {
  return v ? "true" : "false";
}
std::string describeValue(const std::string& v) {
  return v.empty() ? "\"\"" : v;
}
std::string describeValue(const std::vector<double>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + num(v[i]);
  return s + "]";
}
std::string describeValue(const std::vector<std::string>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s + "]";
}
std::string describeValue(const std::vector<std::array<double, 2>>& v) {
  if (v.empty()) return "[]";
  std::ostringstream s;
  s << "[" << v.size() << " points]";
  return s.str();
}
}  // namespace detail

}  // namespace tessera
