// `bench ipc` over our iceoryx transport: leader and follower each a Runtime of one thread with
// ShmTransport exporting its topic and importing the other's (Cap'n Proto Blob messages built in
// loaned chunks).
#include "runtime_actors.hpp"
#include "transports.hpp"

#include <tessera/messages/types.hpp>

#include <chrono>
#include <stdexcept>

namespace tessera::app::ipc {

using namespace std::chrono_literals;

namespace {

ShmTopic blobTopic(const std::string& name, bool exported) {
  ShmTopic t;
  t.name = name;
  t.type = messageTypeOf<msg::Blob>();
  t.exported = exported;
  t.imported = !exported;
  t.importing_processes = 1;
  t.any_reliable = true;
  t.import_policy = MailboxPolicy::reliable(128);
  return t;
}

ShmTransportOptions shmOptions(const std::string& name, std::uint32_t index,
                               std::size_t max_chunk) {
  ShmTransportOptions so;
  so.runtime_name = name;
  so.process_index = index;
  so.max_chunk_bytes = max_chunk;
  return so;
}

}  // namespace

int shmFollower(std::size_t max_chunk, Fill fill, int round) {
  ShmTransport transport(shmOptions(roundName(kShmFollowerName, round), 1, max_chunk));
  Runtime rt(benchRuntimeOptions(1));
  std::atomic<bool> quit{false};
  rt.add("echo", makeEcho(quit, &transport, fill));
  transport.attach(rt, {blobTopic("ping", false), blobTopic("pong", true)});
  rt.configure();
  rt.start();
  transport.startReceiving();
  if (!transport.waitForPublishers(10s)) throw std::runtime_error("follower: no leader");
  // Blocks rather than polls: a thread waking every millisecond is a third party to every
  // wake-up being measured.
  quit.wait(false);
  transport.stopReceiving();
  rt.stop();
  return 0;
}

void shmLeader(std::size_t max_chunk, const Options& o, TransportResult& out, int round) {
  ShmTransport transport(shmOptions(roundName(kShmLeaderName, round), 0, max_chunk));
  Runtime rt(benchRuntimeOptions(1));
  auto& catcher = addCatcher(rt);
  transport.attach(rt, {blobTopic("ping", true), blobTopic("pong", false)});
  const auto link = makeRuntimeLeader(rt, catcher, &transport, o.fill);
  rt.configure();
  rt.start();
  if (!transport.waitForPublishers(10s)) throw std::runtime_error("leader: no follower");
  lead(*link, o, out);
  rt.stop();
}

}  // namespace tessera::app::ipc
