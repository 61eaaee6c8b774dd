// `bench ipc` in process, for reference: the iceoryx transport's actors in one Runtime of two
// threads, messages handed over without a transport.
#include "runtime_actors.hpp"
#include "transports.hpp"

namespace tessera::app::ipc {

void inprocRun(const Options& o, TransportResult& out) {
  Runtime rt(benchRuntimeOptions(2));
  std::atomic<bool> quit{false};
  rt.add("echo", makeEcho(quit, nullptr, o.fill));
  auto& catcher = addCatcher(rt);
  const auto link = makeRuntimeLeader(rt, catcher, nullptr, o.fill);
  rt.configure();
  rt.start();
  lead(*link, o, out);
  rt.stop();
}

}  // namespace tessera::app::ipc
