// FoxgloveServer: an HTTP + WebSocket server speaking Foxglove's WebSocket protocol
// (`foxglove.websocket.v1`, docs/viewer.md#live), which serves Tessera's own web page on the
// same port and lets Foxglove Studio and the page watch a running stack.
//
// Channels are added by the owner; every client gets them advertised and subscribes to what it
// shows. Delivery is keep-latest per client and channel: publish() only replaces the channel's
// newest message, and the server's thread sends each client what it has not seen yet while that
// client's socket has less than `max_buffered_kib` queued. A slow browser therefore never slows
// the publisher and never grows memory: what it missed is counted as drops. A parts channel
// (publishParts) holds keyed parts (map tiles) and sends each client the parts that changed
// since its last message, so incremental updates survive a slow client too.
//
// Clients may publish on topics the owner accepts (acceptClientTopic, the protocol's
// clientPublish): each message goes to the topic's handler, on the server's thread; an error it
// returns goes back to that client as a status message.
//
// Security (docs/viewer.md#security): listens on 127.0.0.1 unless told otherwise; an optional
// token is required on every request (`?token=` or `Authorization: Bearer`); a loopback
// server refuses Host headers other than loopback names (DNS rebinding); browsers' WebSocket
// handshakes must come from the page itself or an allowed origin; client messages above
// max_client_message_kib close the connection; requests are bounded; static files come from an
// in-memory table (no file system path is ever opened). Thread-safe; the server runs one thread
// of its own. Owns its socket; stops in the destructor.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::viewer {

class ServerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FoxgloveServerOptions {
  std::string address = "127.0.0.1";  ///< interface to bind; 0.0.0.0 for every one
  int port = 8765;                    ///< 0: any free port (see FoxgloveServer::port())
  std::string token;                  ///< required on every request when not empty
  std::string name = "tessera";       ///< serverInfo name
  std::vector<std::string> allowed_origins = {"https://app.foxglove.dev"};
  std::size_t max_clients = 16;
  std::size_t max_client_message_kib = 64;  ///< larger client frames close the connection
  std::size_t max_buffered_kib = 4096;      ///< per client: above it nothing more is queued
};

/// A static file the server hands out (the page); `path` starts with '/'.
struct StaticFile {
  std::string path;
  std::string content_type;
  std::string_view body;  ///< not owned: must outlive the server (embedded assets)
};

struct ChannelSpec {
  std::string topic;
  std::string encoding = "json";
  std::string schema_name;
  std::string schema;  ///< JSON Schema text, or empty
  std::string schema_encoding = "jsonschema";
};

class FoxgloveServer {
 public:
  struct Stats {
    std::uint64_t clients = 0;        ///< connected now
    std::uint64_t clients_total = 0;  ///< connections accepted so far
    std::uint64_t messages_sent = 0;  ///< message frames queued to clients
    std::uint64_t bytes_sent = 0;
    std::uint64_t drops = 0;            ///< keep-latest replacements a client never saw
    std::uint64_t rejected = 0;         ///< refused handshakes and HTTP requests
    std::uint64_t protocol_errors = 0;  ///< malformed or invalid client messages
    std::uint64_t client_messages = 0;  ///< client publications accepted by a handler
  };
  /// Handles one client message on an accepted topic; returns "" or an error for the client.
  using ClientHandler = std::function<std::string(std::string_view payload)>;

  /// Binds and starts serving. Throws ServerError naming address:port when it cannot.
  FoxgloveServer(FoxgloveServerOptions options, std::vector<StaticFile> files);
  ~FoxgloveServer();
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  int port() const;  ///< the bound port

  /// Adds a channel (advertised to connected and future clients); returns its id.
  std::uint32_t addChannel(ChannelSpec spec);
  /// The channel's newest message at `stamp_ns` (replaces an unsent one).
  void publish(std::uint32_t channel, std::uint64_t stamp_ns, std::string payload);
  /// Parts channel: `header` replaces the channel's header, `parts` replace those keys' parts;
  /// a new `epoch` first forgets every part. A client's message is
  ///   u8 reset | u32 header bytes | header | u32 n | n x (u32 bytes | part)   (little-endian)
  /// with the parts changed since its last one (all of them, and reset = 1, after a new epoch
  /// or on its first).
  void publishParts(std::uint32_t channel, std::uint64_t stamp_ns, std::uint64_t epoch,
                    std::string header, std::vector<std::pair<std::uint64_t, std::string>> parts);

  /// Every `period_ms` of wall time, while some client subscribes to `channel`, publishes what
  /// `make` returns (called on the server's thread; it must be thread-safe). For figures that
  /// are cheap to take but pointless to push when nobody looks (live metrics).
  void publishEvery(std::uint32_t channel, int period_ms, std::function<std::string()> make);

  /// Calls `handler(channel)` (on the server's thread, the subscription in place) when a client
  /// subscribes to a keep-latest channel that holds no message yet: a publisher that converts
  /// only while someone subscribes can publish its newest message then (a map sent once before
  /// anyone looked).
  void onSubscribe(std::function<void(std::uint32_t channel)> handler);

  /// Whether some client subscribes to `channel` (skip converting messages nobody sees).
  bool subscribed(std::uint32_t channel) const;

  /// Lets clients publish on `topic` (any encoding; the handler decides what it reads).
  void acceptClientTopic(const std::string& topic, ClientHandler handler);

  Stats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera::viewer
