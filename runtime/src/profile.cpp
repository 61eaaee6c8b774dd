#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/registry.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace tessera {

namespace {

std::string at(const std::string& path, const YAML::Node& n) {
  return n.Mark().line >= 0 ? path + ":" + std::to_string(n.Mark().line + 1) : path;
}

std::string atKey(const std::string& path, const YAML::const_iterator::value_type& kv) {
  return kv.first.Mark().line >= 0 ? path + ":" + std::to_string(kv.first.Mark().line + 1) : path;
}

std::string scalar(const std::string& path, const YAML::Node& n, const std::string& key) {
  if (!n.IsScalar()) throw ConfigError(at(path, n) + ": " + key + ": expected a string");
  return n.Scalar();
}

double number(const std::string& path, const YAML::Node& n, const std::string& key) {
  try {
    if (n.IsScalar()) return n.as<double>();
  } catch (const YAML::Exception&) {
  }
  throw ConfigError(at(path, n) + ": " + key + ": expected a number, got '" +
                    (n.IsScalar() ? n.Scalar() : std::string("a collection")) + "'");
}

YAML::Node parseValue(const std::string& text) {
  try {
    YAML::Node n = YAML::Load(text);
    if (n.IsNull() && !text.empty() && text != "null" && text != "~") return YAML::Node(text);
    return n;
  } catch (const YAML::Exception&) {
    return YAML::Node(text);
  }
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string part; std::getline(ss, part, sep);) out.push_back(part);
  return out;
}

const std::set<std::string> kTopKeys = {"name",     "description",    "clock",
                                        "sim_rate", "max_duration_s", "actors",
                                        "restart",  "external",       "dds"};
const std::set<std::string> kActorKeys = {"type", "process", "remap", "namespace", "params"};

void applyOverride(YAML::Node root, const std::string& text, const std::string& path) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw ConfigError("--set " + text + ": expected KEY=VALUE or ACTOR.KEY=VALUE");
  }
  const std::string key = text.substr(0, eq);
  const YAML::Node value = parseValue(text.substr(eq + 1));
  auto parts = split(key, '.');
  YAML::Node actors = root["actors"];
  if (parts.size() == 1 && kTopKeys.count(key) && key != "actors") {
    root[key] = value;
    return;
  }
  if (parts.size() == 2 && parts[0] == "dds") {  // dds.partition=..., dds.domain=...
    root["dds"][parts[1]] = value;
    return;
  }
  const auto entryOf = [&](const YAML::Node& actor) -> const ActorRegistry::Entry* {
    const YAML::Node type = actor["type"];
    return type && type.IsScalar() ? ActorRegistry::instance().find(type.Scalar()) : nullptr;
  };
  const auto movedError = [&](const std::string& actor, const std::string& param) {
    const auto* entry = entryOf(actors[actor]);
    if (entry == nullptr) return;
    for (const auto& r : entry->renamed) {
      if (param != r.old_key) continue;
      std::string moved;  // each new key with the actor in front
      for (const auto& k : split(r.new_key, ' ')) moved += (k == "and" ? " and " : actor + "." + k);
      throw ConfigError("--set " + text + ": moved to " + moved);
    }
  };
  const bool names_actor = actors && actors.IsMap() && parts.size() > 1 && actors[parts[0]];
  if (!names_actor && actors && actors.IsMap()) {
    // A parameter name without an actor (`particles`, `rbpf.particles`): the one actor whose
    // options declare it.
    std::vector<std::string> owners;
    for (const auto& kv : actors) {
      const auto* entry = entryOf(kv.second);
      if (entry == nullptr) continue;
      for (const auto& row : entry->options()) {
        if (row[0] == key) owners.push_back(kv.first.as<std::string>());
      }
    }
    if (owners.empty()) {
      for (const auto& kv : actors) movedError(kv.first.as<std::string>(), key);
    }
    if (owners.size() > 1) {
      std::string list;
      for (const auto& o : owners) list += (list.empty() ? "" : ", ") + o + "." + key;
      throw ConfigError("--set " + text + ": '" + key +
                        "' is a parameter of several actors; use one of " + list);
    }
    if (owners.size() == 1) parts.insert(parts.begin(), owners.front());
  }
  if (parts.size() == 1) {
    throw ConfigError("--set " + text + ": no profile key or actor parameter named '" + key +
                      "' in " + path);
  }
  if (!actors || !actors.IsMap() || !actors[parts[0]]) {
    throw ConfigError("--set " + text + ": no actor named '" + parts[0] + "' in " + path);
  }
  YAML::Node actor = actors[parts[0]];
  if (parts.size() == 2 && (parts[1] == "type" || parts[1] == "process")) {
    actor[parts[1]] = value;
    return;
  }
  if (parts.size() == 2) movedError(parts[0], parts[1]);
  if (!actor["params"] || actor["params"].IsNull())
    actor["params"] = YAML::Node(YAML::NodeType::Map);
  YAML::Node node = actor["params"];
  for (std::size_t i = 1; i + 1 < parts.size(); ++i) {
    if (!node[parts[i]] || !node[parts[i]].IsMap())
      node[parts[i]] = YAML::Node(YAML::NodeType::Map);
    // reset(), not `=`: assigning a yaml-cpp node replaces the content it refers to.
    node.reset(node[parts[i]]);
  }
  node[parts.back()] = value;
}

/// `external: {inputs: [topic, ...], outputs: [topic, ...]}`.
void parseExternal(const std::string& path, const YAML::Node& external, Profile& p) {
  if (!external.IsMap()) {
    throw ConfigError(at(path, external) +
                      ": external: expected a mapping with 'inputs' and/or 'outputs'");
  }
  for (const auto& kv : external) {
    const std::string key = kv.first.as<std::string>();
    if (key != "inputs" && key != "outputs") {
      throw ConfigError(atKey(path, kv) + ": external: unknown key '" + key +
                        "' (known: inputs, outputs)");
    }
    if (!kv.second.IsSequence()) {
      throw ConfigError(at(path, kv.second) + ": external." + key +
                        ": expected a list of topic names");
    }
    auto& out = key == "inputs" ? p.external_inputs : p.external_outputs;
    for (const auto& t : kv.second) {
      const std::string topic = scalar(path, t, "external." + key);
      if (topic.empty())
        throw ConfigError(at(path, t) + ": external." + key + ": empty topic name");
      out.push_back(topic);
    }
  }
}

/// Each external input is subscribed and each external output published by some actor.
void checkExternal(const Profile& profile, const Runtime& rt) {
  const auto check = [&](const std::vector<std::string>& topics, bool inputs) {
    for (const auto& topic : topics) {
      bool used = false;
      for (const auto& a : profile.actors) {
        const auto list = inputs ? rt.subscriptionsOf(a.name) : rt.publicationsOf(a.name);
        used = used || std::find(list.begin(), list.end(), topic) != list.end();
      }
      if (!used) {
        throw ConfigError(profile.path + ": external." + (inputs ? "inputs" : "outputs") +
                          ": no actor " + (inputs ? "subscribes to" : "publishes") + " topic '" +
                          topic + "'");
      }
    }
  };
  check(profile.external_inputs, true);
  check(profile.external_outputs, false);
}

}  // namespace

Profile parseProfile(const std::string& yaml_text, const std::string& path,
                     const std::vector<std::string>& overrides) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(path + ":" + std::to_string(e.mark.line + 1) +
                      ": YAML syntax error: " + e.msg);
  }
  if (!root || !root.IsMap())
    throw ConfigError(path + ": expected a YAML mapping at the top level");
  for (const auto& o : overrides) applyOverride(root, o, path);

  Profile p;
  p.path = path;
  p.name = std::filesystem::path(path).stem().string();
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (!kTopKeys.count(key)) {
      throw ConfigError(atKey(path, kv) + ": unknown key '" + key +
                        "' (known: name, description, clock, sim_rate, max_duration_s, actors, "
                        "restart, external, dds)");
    }
  }
  if (root["name"]) p.name = scalar(path, root["name"], "name");
  if (root["description"]) p.description = scalar(path, root["description"], "description");
  if (root["clock"]) {
    const std::string c = scalar(path, root["clock"], "clock");
    if (c == "sim")
      p.clock = ClockKind::kSimulated;
    else if (c == "wall")
      p.clock = ClockKind::kWall;
    else if (c == "paced")
      p.clock = ClockKind::kPaced;
    else
      throw ConfigError(at(path, root["clock"]) +
                        ": clock: expected 'sim', 'wall' or 'paced', got '" + c + "'");
  }
  if (root["sim_rate"]) {
    p.sim_rate = number(path, root["sim_rate"], "sim_rate");
    if (!(p.sim_rate >= 0))
      throw ConfigError(at(path, root["sim_rate"]) + ": sim_rate must be >= 0");
  }
  if (root["max_duration_s"]) {
    p.max_duration_s = number(path, root["max_duration_s"], "max_duration_s");
    if (!(p.max_duration_s >= 0))
      throw ConfigError(at(path, root["max_duration_s"]) + ": max_duration_s must be >= 0");
  }
  if (const YAML::Node restart = root["restart"]) {
    if (!restart.IsSequence()) {
      throw ConfigError(at(path, restart) + ": restart: expected a list of process names");
    }
    for (const auto& r : restart) p.restart.push_back(scalar(path, r, "restart"));
  }
  if (const YAML::Node external = root["external"]) parseExternal(path, external, p);
  if (const YAML::Node dds = root["dds"]) {
    if (!dds.IsMap()) {
      throw ConfigError(at(path, dds) +
                        ": dds: expected a mapping (domain, partition, interface, peers, ...)");
    }
    p.dds = Params(dds, path + ": dds");
    p.has_dds = true;
  }
  const YAML::Node actors = root["actors"];
  if (!actors || !actors.IsMap() || actors.size() == 0) {
    throw ConfigError(path +
                      ": 'actors' must be a non-empty mapping of name: {type: ..., params: ...}");
  }
  for (const auto& kv : actors) {
    ActorSpec spec;
    spec.name = kv.first.as<std::string>();
    spec.line = kv.first.Mark().line + 1;
    const YAML::Node& a = kv.second;
    const std::string where = path + ": actors." + spec.name;
    if (!a.IsMap())
      throw ConfigError(atKey(path, kv) + ": actor '" + spec.name +
                        "': expected a mapping with 'type'");
    for (const auto& field : a) {
      const std::string f = field.first.as<std::string>();
      if (!kActorKeys.count(f)) {
        throw ConfigError(atKey(path, field) + ": actors." + spec.name + ": unknown key '" + f +
                          "' (known: type, process, remap, namespace, params)");
      }
    }
    if (!a["type"])
      throw ConfigError(atKey(path, kv) + ": actors." + spec.name + ": missing 'type'");
    spec.type = scalar(path, a["type"], "actors." + spec.name + ".type");
    if (!ActorRegistry::instance().find(spec.type)) {
      std::string known;
      for (const auto& [name, _] : ActorRegistry::instance().entries())
        known += (known.empty() ? "" : ", ") + name;
      throw ConfigError(at(path, a["type"]) + ": actors." + spec.name +
                        ".type: unknown actor type '" + spec.type + "' (known: " + known + ")");
    }
    if (a["process"]) spec.process = scalar(path, a["process"], "actors." + spec.name + ".process");
    if (a["remap"]) {
      if (!a["remap"].IsMap())
        throw ConfigError(at(path, a["remap"]) + ": actors." + spec.name +
                          ".remap: expected a mapping local: global");
      for (const auto& r : a["remap"]) {
        spec.remap[r.first.as<std::string>()] =
            scalar(path, r.second, "actors." + spec.name + ".remap");
      }
    }
    if (a["namespace"]) {
      spec.topic_namespace = scalar(path, a["namespace"], "actors." + spec.name + ".namespace");
      const auto& n = spec.topic_namespace;
      if (!isTopicNamespace(n))
        throw ConfigError(at(path, a["namespace"]) + ": actors." + spec.name + ".namespace: '" + n +
                          "' is not a namespace (expected letters, digits, '_' and inner '/', "
                          "e.g. r1 or fleet/r1)");
    }
    const std::string params_where = (a["params"] && a["params"].Mark().line >= 0)
                                         ? path + ": actors." + spec.name + ".params"
                                         : where + ".params";
    spec.params = Params(a["params"] ? a["params"] : YAML::Node(YAML::NodeType::Map), params_where);
    p.actors.push_back(std::move(spec));
  }
  return p;
}

bool isTopicNamespace(std::string_view n) {
  return !n.empty() && n.front() != '/' && n.back() != '/' && n.find("//") == n.npos &&
         std::all_of(n.begin(), n.end(), [](char c) {
           return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '/';
         });
}

std::string globalTopicName(const std::map<std::string, std::string>& remap,
                            const std::string& topic_namespace, const std::string& local) {
  if (const auto it = remap.find(local); it != remap.end()) return it->second;
  return topic_namespace.empty() ? local : topic_namespace + "/" + local;
}

Profile loadProfile(const std::string& path, const std::vector<std::string>& overrides) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open profile file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parseProfile(ss.str(), path, overrides);
}

namespace {
std::unique_ptr<Runtime> build(const Profile& profile, RuntimeOptions options,
                               const std::string* process,
                               const std::function<void(Runtime&)>& before_configure,
                               bool allow_unpublished = false) {
  if (profile.clock == ClockKind::kPaced && !(profile.sim_rate > 0))
    throw ConfigError(profile.path +
                      ": clock 'paced' needs sim_rate > 0 (simulated seconds per "
                      "wall second, e.g. --rate 10)");
  options.clock = profile.clock;
  options.sim_rate = profile.sim_rate;
  options.max_sim_duration = secondsToNanos(profile.max_duration_s);
  options.external_inputs = profile.external_inputs;
  auto runtime = std::make_unique<Runtime>(options);
  for (const auto& spec : profile.actors) {
    if (process != nullptr && spec.process != *process) continue;
    std::unique_ptr<Actor> actor;
    try {
      actor = ActorRegistry::instance().create(spec.type, spec.params);
    } catch (const ConfigError& e) {
      throw ConfigError(std::string(e.what()));
    } catch (const std::exception& e) {
      throw ConfigError(profile.path + ":" + std::to_string(spec.line) + ": actor '" + spec.name +
                        "' (" + spec.type + "): " + e.what());
    }
    runtime->add(spec.name, std::move(actor), spec.remap, spec.topic_namespace);
  }
  if (before_configure) before_configure(*runtime);
  try {
    runtime->configure(allow_unpublished);
  } catch (const ConfigError& e) {
    throw ConfigError(profile.path + ": " + e.what());
  }
  if (process == nullptr && !allow_unpublished) checkExternal(profile, *runtime);
  return runtime;
}
}  // namespace

std::unique_ptr<Runtime> buildRuntime(const Profile& profile, RuntimeOptions options) {
  return build(profile, std::move(options), nullptr, {});
}

std::unique_ptr<Runtime> buildWiringRuntime(const Profile& profile, RuntimeOptions options) {
  return build(profile, std::move(options), nullptr, {}, true);
}

std::unique_ptr<Runtime> buildProcessRuntime(
    const Profile& profile, RuntimeOptions options, const std::string& process,
    const std::function<void(Runtime&)>& before_configure) {
  return build(profile, std::move(options), &process, before_configure);
}

std::string resolveProfilePath(const std::string& name_or_path,
                               const std::vector<std::string>& search_dirs) {
  namespace fs = std::filesystem;
  std::vector<std::string> tried{name_or_path};
  if (fs::is_regular_file(name_or_path)) return name_or_path;
  for (const auto& dir : search_dirs) {
    for (const auto& candidate :
         {fs::path(dir) / name_or_path, fs::path(dir) / (name_or_path + ".yaml")}) {
      tried.push_back(candidate.string());
      if (fs::is_regular_file(candidate)) return candidate.string();
    }
  }
  std::string list;
  for (const auto& t : tried) list += "\n  " + t;
  throw ConfigError("profile '" + name_or_path + "' not found; tried:" + list);
}

}  // namespace tessera
