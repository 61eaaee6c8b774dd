// FoxgloveClient: the client side of Foxglove's WebSocket protocol, for the command line
// (`tessera topics`, `tessera echo`) to look into a running stack through its viewer
// (docs/viewer.md#topics-and-echo). Connects, reads the server's channels, subscribes, and hands
// out message data in arrival order. Thread-safe; runs one network thread of its own; closes in
// the destructor.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::viewer {

struct RemoteChannel {
  std::uint32_t id = 0;
  std::string topic, encoding, schema_name;
};

struct RemoteMessage {
  std::uint32_t channel = 0;  ///< the channel's id
  std::uint64_t stamp_ns = 0;
  std::string payload;
};

class FoxgloveClient {
 public:
  /// Connects to `url` (ws://HOST:PORT[/?token=T]) and waits up to `timeout_ms` for the server's
  /// channels. Throws ServerError (foxglove_server.hpp) saying what failed: nothing listening,
  /// refused (token, Host, Origin), not a Foxglove server, no answer in time.
  explicit FoxgloveClient(const std::string& url, int timeout_ms = 3000);
  ~FoxgloveClient();
  FoxgloveClient(const FoxgloveClient&) = delete;
  FoxgloveClient& operator=(const FoxgloveClient&) = delete;

  std::string serverName() const;
  std::vector<RemoteChannel> channels() const;
  /// Subscribes to a channel by id (messages then arrive through next()).
  void subscribe(std::uint32_t channel);
  /// The next message, waiting up to `timeout_ms`; nothing on timeout or once closed.
  std::optional<RemoteMessage> next(int timeout_ms);
  bool closed() const;
  /// Messages the client let go because the caller did not take them fast enough (the
  /// client keeps at most 1024).
  std::uint64_t dropped() const;
  /// CPU time of the client's network thread so far [s] (benchmarks subtract a client's own
  /// cost from the process's).
  double networkCpuSeconds() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera::viewer
