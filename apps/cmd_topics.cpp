// `tessera topics` and `tessera echo TOPIC`: look into a running stack through its viewer
// (`tessera run PROFILE --view PORT`), with the Foxglove WebSocket protocol the viewer speaks
// (docs/viewer.md#topics-and-echo). Messages print as the viewer sends them: Foxglove's JSON for
// scans, grids and poses, Tessera's own JSON for the rest, one message per line.
#include "commands.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/viewer/foxglove_client.hpp>
#include <tessera/viewer/foxglove_server.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <iomanip>
#include <iostream>
#include <map>

namespace tessera::app {

namespace {

std::atomic<bool> g_stop{false};
void onSignal(int) {
  g_stop.store(true);
}

std::string urlFor(const std::string& url, int port, const std::string& token) {
  std::string u = url.empty() ? "ws://127.0.0.1:" + std::to_string(port) : url;
  if (!token.empty()) u += (u.find('?') == std::string::npos ? "/?token=" : "&token=") + token;
  return u;
}

struct Target {
  std::string url;
  int port = 8765;
  std::string token;
  void add(CLI::App& cmd) {
    cmd.add_option("--port", port, "the viewer's port on this machine (--view PORT)");
    cmd.add_option("--url", url, "the viewer's WebSocket URL instead (ws://HOST:PORT)");
    cmd.add_option("--token", token, "the viewer's token (--view-token)");
  }
};

}  // namespace

void addTopicsCommands(CLI::App& app, int& result) {
  auto* topics = app.add_subcommand(
      "topics", "list the topics of a running stack with a viewer (tessera run ... --view PORT)");
  auto t = std::make_shared<Target>();
  auto hz = std::make_shared<double>(0);
  t->add(*topics);
  topics->add_option("--hz", *hz, "also measure each topic's rate over this many seconds");
  topics->callback([t, hz, &result] {
    const std::string url = urlFor(t->url, t->port, t->token);
    viewer::FoxgloveClient client(url);
    const auto channels = client.channels();
    std::cout << client.serverName() << " at " << (t->url.empty() ? url : t->url) << ": "
              << channels.size() << " topics\n";
    std::map<std::uint32_t, std::uint64_t> counts;
    if (*hz > 0) {
      for (const auto& c : channels) client.subscribe(c.id);
      const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(*hz);
      while (std::chrono::steady_clock::now() < end) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
            end - std::chrono::steady_clock::now());
        if (auto m = client.next(static_cast<int>(std::max<long>(1, left.count()))))
          ++counts[m->channel];
      }
    }
    for (const auto& c : channels) {
      std::cout << "  " << std::left << std::setw(24) << c.topic << std::setw(26)
                << (c.schema_name.empty() ? "(json)" : c.schema_name) << c.encoding;
      if (*hz > 0)
        std::cout << "  " << std::fixed << std::setprecision(1)
                  << static_cast<double>(counts[c.id]) / *hz << " Hz";
      std::cout << "\n";
    }
    result = 0;
  });

  auto* echo = app.add_subcommand(
      "echo", "print a topic's messages from a running stack with a viewer, one per line");
  auto e = std::make_shared<Target>();
  struct EchoArgs {
    std::string topic;
    long count = 0;
    double timeout = 0;
  };
  auto a = std::make_shared<EchoArgs>();
  echo->add_option("topic", a->topic, "topic to print (see tessera topics)")->required();
  e->add(*echo);
  echo->add_option("-n,--count", a->count, "stop after this many messages (0: until Ctrl-C)");
  echo->add_option("--timeout", a->timeout,
                   "give up when nothing arrives for this many seconds (0: wait)");
  echo->callback([e, a, &result] {
    viewer::FoxgloveClient client(urlFor(e->url, e->port, e->token));
    const auto channels = client.channels();
    const viewer::RemoteChannel* channel = nullptr;
    for (const auto& c : channels)
      if (c.topic == a->topic) channel = &c;
    if (!channel) {
      std::string known;
      for (const auto& c : channels) known += (known.empty() ? "" : ", ") + c.topic;
      throw ConfigError("no topic '" + a->topic + "' on " + client.serverName() +
                        " (topics: " + known + ")");
    }
    const bool text = channel->encoding == "json";
    client.subscribe(channel->id);
    g_stop = false;
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
    long printed = 0;
    auto last = std::chrono::steady_clock::now();
    result = 0;
    while (!g_stop && (a->count <= 0 || printed < a->count)) {
      auto m = client.next(200);
      if (!m) {
        if (client.closed()) {
          std::cerr << "echo: the viewer closed the connection (the run ended)\n";
          break;
        }
        if (a->timeout > 0 &&
            std::chrono::steady_clock::now() - last > std::chrono::duration<double>(a->timeout)) {
          std::cerr << "echo: nothing on '" << a->topic << "' for " << a->timeout << " s\n";
          result = 1;
          break;
        }
        continue;
      }
      last = std::chrono::steady_clock::now();
      if (text)
        std::cout << m->payload << "\n";
      else
        std::cout << "{\"encoding\":\"" << channel->encoding << "\",\"bytes\":" << m->payload.size()
                  << "}\n";
      std::cout.flush();
      ++printed;
    }
    std::signal(SIGINT, SIG_DFL);
    std::signal(SIGTERM, SIG_DFL);
    if (client.dropped() > 0)
      std::cerr << "echo: " << client.dropped() << " messages skipped (printing was too slow)\n";
  });
}

}  // namespace tessera::app
