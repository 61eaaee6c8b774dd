#include <tessera/runtime/registry.hpp>

namespace tessera {

ActorRegistry& ActorRegistry::instance() {
  static ActorRegistry registry;
  return registry;
}

void ActorRegistry::add(const std::string& type, Entry entry) {
  if (!entries_.emplace(type, std::move(entry)).second) {
    throw std::logic_error("actor type '" + type + "' registered twice");
  }
}

const ActorRegistry::Entry* ActorRegistry::find(const std::string& type) const {
  auto it = entries_.find(type);
  return it == entries_.end() ? nullptr : &it->second;
}

std::unique_ptr<Actor> ActorRegistry::create(const std::string& type, const Params& params) const {
  const Entry* e = find(type);
  if (e == nullptr) {
    std::string known;
    for (const auto& [name, _] : entries_) known += (known.empty() ? "" : ", ") + name;
    throw ConfigError("unknown actor type '" + type + "' (known types: " + known + ")");
  }
  return e->create(params);
}

}  // namespace tessera
