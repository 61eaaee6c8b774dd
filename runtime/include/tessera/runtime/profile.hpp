// App profiles: YAML files (apps/profiles/*.yaml) naming the actors of a deployment.
//
//   name: sim_mapping
//   description: simulated office, mapping with known poses
//   clock: sim            # sim | wall
//   sim_rate: 0           # sim clock: 0 = as fast as possible, 1 = real time
//   max_duration_s: 0     # stop after this much data time (0 = until the inputs end)
//   restart: [mapper]     # `tessera launch`: processes restarted when they die (wall clock)
//   external:             # topics programs outside the profile use while it runs
//     inputs: [goal]      #   published from outside (`tessera goal`): a subscriber needs no
//                         #   publisher in the profile
//     outputs: [nav_status]   # read from outside: crosses shared memory under `tessera launch`
//   dds:                  # `tessera launch --host`: topics between hosts (tessera/dds)
//     partition: lab_a    #   required; domain, interface, peers, compression: {topic: level}
//   actors:
//     sim:                # instance name
//       type: simulator   # registered actor type (tessera actors lists them)
//       process: robot    # process group for `tessera launch` (default: main)
//       remap: {scan: /front/scan}   # local topic -> global topic
//       namespace: r1     # topics not remapped are r1/<local name> (several robots' actors)
//       params: {world: builtin:office}
//
// --set overrides: "ACTOR.KEY=VALUE" sets params.KEY of ACTOR (nested keys with more dots);
// "KEY=VALUE" sets a top-level key (clock, sim_rate, max_duration_s) or, if no such key
// exists, the parameter KEY of the only actor whose options have it. Unknown keys, wrong types,
// unknown actor types and topics nobody publishes are ConfigErrors naming file, line and key.
#pragma once

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/runtime.hpp>

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace tessera {

struct ActorSpec {
  std::string name;
  std::string type;
  std::string process = "main";
  Params params;
  std::map<std::string, std::string> remap;
  std::string topic_namespace;  // `namespace:`: prefix of the topics not remapped
  int line = 0;                 // 1-based line of the actor's entry in the profile
};

struct Profile {
  std::string path;
  std::string name;
  std::string description;
  ClockKind clock = ClockKind::kSimulated;
  double sim_rate = 0.0;
  double max_duration_s = 0.0;
  std::vector<ActorSpec> actors;
  std::vector<std::string> restart;  // process names `tessera launch` restarts when they die
  /// Topics a program outside the deployment publishes (e.g. `tessera goal`), and topics it
  /// reads. Each input must be subscribed and each output published by an actor of the profile.
  std::vector<std::string> external_inputs, external_outputs;
  /// The `dds:` section as written (read by tessera/dds's loadDdsOptions); has_dds when given.
  Params dds;
  bool has_dds = false;
};

/// A topic namespace (an actor's `namespace:`, a robot's prefix): letters, digits, '_' and '/'
/// between non-empty parts, e.g. "r1" or "fleet/r1".
bool isTopicNamespace(std::string_view name);

/// The global name of an actor's local topic: its remap if one is given, else the local name under
/// the actor's namespace ("ns/local"), else the local name itself.
std::string globalTopicName(const std::map<std::string, std::string>& remap,
                            const std::string& topic_namespace, const std::string& local);

/// Parses and validates a profile file, applying --set overrides in order. Throws ConfigError.
Profile loadProfile(const std::string& path, const std::vector<std::string>& overrides = {});
/// Same, from YAML text (`path` only names it in errors).
Profile parseProfile(const std::string& yaml_text, const std::string& path,
                     const std::vector<std::string>& overrides = {});

/// Creates every actor through the ActorRegistry and adds it to a new runtime, then configures
/// it. Option errors are rethrown as ConfigError naming the profile file and actor.
std::unique_ptr<Runtime> buildRuntime(const Profile& profile, RuntimeOptions options);

/// Same, but a subscription without a publisher is allowed: the wiring of part of a deployment
/// (a runtime that is never run).
std::unique_ptr<Runtime> buildWiringRuntime(const Profile& profile, RuntimeOptions options);

/// Same for one process of a multi-process deployment: only the actors whose `process` is
/// `process`; `before_configure` wires the cross-process topics.
std::unique_ptr<Runtime> buildProcessRuntime(const Profile& profile, RuntimeOptions options,
                                             const std::string& process,
                                             const std::function<void(Runtime&)>& before_configure);

/// Finds a profile by name or path: the path as given, else NAME or NAME.yaml in each of
/// `search_dirs`. Throws ConfigError listing what it tried.
std::string resolveProfilePath(const std::string& name_or_path,
                               const std::vector<std::string>& search_dirs);

}  // namespace tessera
