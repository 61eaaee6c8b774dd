// ActorRegistry: actors are created by type name, so a profile can say `type: grid_mapper` and
// adding an actor never edits the runtime or the CLI. Register next to the actor's definition:
//
//   TESSERA_REGISTER_ACTOR("grid_mapper", GridMapperActor, GridMapperOptions,
//                          "occupancy grid mapping with known poses");
//
// The actor class must be constructible from its options struct. Libraries that register
// actors are linked whole-archive so the registration objects are kept.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <array>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

class ActorRegistry {
 public:
  using Factory = std::function<std::unique_ptr<Actor>(const Params&)>;
  using Describer = std::function<std::vector<std::array<std::string, 3>>()>;
  struct Entry {
    Factory create;
    Describer options;
    std::string summary;
    std::span<const RenamedKey> renamed;  ///< option keys that moved (see options.hpp)
  };

  static ActorRegistry& instance();
  void add(const std::string& type, Entry entry);
  /// Throws ConfigError listing the known types when `type` is unknown.
  std::unique_ptr<Actor> create(const std::string& type, const Params& params) const;
  const Entry* find(const std::string& type) const;
  const std::map<std::string, Entry>& entries() const { return entries_; }

 private:
  std::map<std::string, Entry> entries_;
};

namespace detail {
struct ActorRegistration {
  ActorRegistration(const char* type, ActorRegistry::Entry entry) {
    ActorRegistry::instance().add(type, std::move(entry));
  }
};
}  // namespace detail

}  // namespace tessera

#define TESSERA_REGISTER_ACTOR(type_name, ActorClass, OptionsClass, summary_text)       \
  static const ::tessera::detail::ActorRegistration tessera_registration_##ActorClass { \
    type_name, ::tessera::ActorRegistry::Entry {                                        \
      [](const ::tessera::Params& p) -> std::unique_ptr<::tessera::Actor> {             \
        return std::make_unique<ActorClass>(::tessera::loadOptions<OptionsClass>(p));   \
      },                                                                                \
          [] { return ::tessera::describeOptions<OptionsClass>(); }, summary_text,      \
          ::tessera::renamedKeys<OptionsClass>()                                        \
    }                                                                                   \
  }
