// `bench ipc` transports, each a leader and a follower running the protocol (protocol.hpp):
//  * iceoryx      our shared-memory transport (transport_iceoryx.cpp)
//  * iceoryx_raw  raw iceoryx chunks, the floor (transport_raw.cpp)
//  * uds          a Unix-domain stream socket (transport_uds.cpp)
//  * inproc       the same actors as iceoryx in one Runtime, no transport (transport_inproc.cpp)
// The process transports' leaders and followers run in forked children (processes.hpp); a
// follower returns its exit code, a leader writes the round into `out`.
#pragma once

#include "protocol.hpp"

#include <cstddef>
#include <string>

namespace tessera::app::ipc {

// iceoryx runtime names of the children; each round's get the round's number appended (a name
// is registered once per RouDi).
constexpr char kShmLeaderName[] = "tessera_bench_ipc_leader";
constexpr char kShmFollowerName[] = "tessera_bench_ipc_follower";
constexpr char kRawLeaderName[] = "tessera_bench_ipc_raw_leader";
constexpr char kRawFollowerName[] = "tessera_bench_ipc_raw_follower";
inline std::string roundName(const char* base, int round) {
  return std::string(base) + "_" + std::to_string(round);
}

// iceoryx: one Runtime per process over ShmTransport; `max_chunk` as RouDi's pools allow.
int shmFollower(std::size_t max_chunk, Fill fill, int round);
void shmLeader(std::size_t max_chunk, const Options& o, TransportResult& out, int round);

// iceoryx_raw: UntypedPublisher/UntypedSubscriber and a WaitSet in each process.
int rawFollower(Fill fill, int round);
void rawLeader(const Options& o, TransportResult& out, int round);

// uds: the two ends of a SocketPair, one per process.
/// A connected Unix-domain socket pair, closed when this goes.
class SocketPair {
 public:
  SocketPair();
  ~SocketPair();
  SocketPair(const SocketPair&) = delete;
  SocketPair& operator=(const SocketPair&) = delete;
  int fds[2] = {-1, -1};
};
int udsFollower(int fd, Fill fill);
void udsLeader(int fd, const Options& o, TransportResult& out);

// inproc: leader and follower in one Runtime of this process.
void inprocRun(const Options& o, TransportResult& out);

}  // namespace tessera::app::ipc
