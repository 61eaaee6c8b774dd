// `bench ipc` actors that run the protocol inside a Runtime: the follower's Echo (a pong per
// ping) and the leader's link (an external publisher for pings, a Catcher actor taking pongs).
// Shared by the iceoryx transport (a Runtime per process over ShmTransport) and by inproc (both
// ends in one Runtime).
#pragma once

#include "protocol.hpp"

#include <tessera/runtime/runtime.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <atomic>
#include <memory>

namespace tessera::app::ipc {

/// Options of the benchmark's Runtimes: wall clock, `threads` executor threads, no progress.
RuntimeOptions benchRuntimeOptions(int threads);

/// The follower: answers pings on "ping" with pongs on "pong" and sets (and notifies) `quit` when
/// told to. `transport` (nullptr in process) counts the messages it copied.
std::unique_ptr<Actor> makeEcho(std::atomic<bool>& quit, const ShmTransport* transport, Fill fill);

/// Takes pongs on "pong" for the leader's thread.
class Catcher;
/// Adds a Catcher named "catcher" to `rt`.
Catcher& addCatcher(Runtime& rt);

/// The leader's link: pings through an external publisher on "ping", pongs from `catcher`. With
/// a transport, pongs are received on the calling thread (ShmTransport::receiveHere), as raw
/// iceoryx's leader does: the thread that sent the ping is the one its pong wakes.
std::unique_ptr<LeaderLink> makeRuntimeLeader(Runtime& rt, Catcher& catcher,
                                              ShmTransport* transport, Fill fill);

}  // namespace tessera::app::ipc
