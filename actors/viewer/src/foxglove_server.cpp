// The Foxglove WebSocket server over websocketpp + standalone asio. websocketpp 0.8 does not
// compile as C++20, so this file (and only it) is built as C++17 (actors/viewer/CMakeLists.txt);
// its header keeps websocketpp out of everyone else's includes.
#include <tessera/viewer/foxglove_server.hpp>

#include "little_endian.hpp"

#define ASIO_STANDALONE
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <thread>

namespace tessera::viewer {

namespace {

using Server = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;
using detail::appendLe;
using detail::readLe;
using nlohmann::json;
namespace http_status = websocketpp::http::status_code;

const char* const kSubprotocol = "foxglove.websocket.v1";

bool equalConstantTime(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d |= static_cast<unsigned char>(a[i] ^ b[i]);
  return d == 0;
}

std::string queryValue(const std::string& resource, const std::string& key) {
  const auto q = resource.find('?');
  if (q == std::string::npos) return {};
  std::size_t at = q + 1;
  while (at <= resource.size()) {
    auto end = resource.find('&', at);
    if (end == std::string::npos) end = resource.size();
    const std::string item = resource.substr(at, end - at);
    const auto eq = item.find('=');
    if (eq != std::string::npos && item.substr(0, eq) == key) return item.substr(eq + 1);
    at = end + 1;
  }
  return {};
}

std::string hostName(const std::string& host) {
  if (!host.empty() && host[0] == '[') {  // [::1]:8765
    const auto close = host.find(']');
    return close == std::string::npos ? host : host.substr(0, close + 1);
  }
  return host.substr(0, host.find(':'));
}

bool isLoopbackAddress(const std::string& address) {
  return address == "127.0.0.1" || address == "localhost" || address == "::1";
}

}  // namespace

struct FoxgloveServer::Impl {
  struct Channel {
    ChannelSpec spec;
    bool parts = false;
    // keep-latest channels
    std::shared_ptr<const std::string> payload;
    std::uint64_t stamp_ns = 0;
    std::uint64_t version = 0;  // messages published (keep-latest channels)
    // parts channels
    std::uint64_t epoch = 0;
    bool has_epoch = false;
    std::string header;
    std::map<std::uint64_t, std::pair<std::uint64_t, std::string>> part;  // key -> version, bytes
    std::uint64_t part_version = 0;
  };
  struct Subscription {
    std::uint32_t channel = 0;
    std::uint64_t sent = 0;  // channel version (or part version) this client has
    std::uint64_t epoch = 0;
    bool has_epoch = false;
  };
  struct Client {
    std::map<std::uint32_t, Subscription> subscriptions;  // by the client's subscription id
    std::map<std::uint32_t, std::string> advertised;      // client channel id -> topic
  };

  FoxgloveServerOptions options;
  std::map<std::string, std::string_view> bodies;
  std::map<std::string, std::string> content_types;
  Server server;
  std::thread thread;
  int bound_port = 0;
  // One per server: clients treat a new session id as a restarted server and start over.
  std::string session_id =
      std::to_string(std::chrono::system_clock::now().time_since_epoch().count());

  mutable std::mutex mutex;  // everything below
  std::vector<Channel> channels;
  std::map<Hdl, Client, std::owner_less<Hdl>> clients;
  std::map<std::string, ClientHandler> client_topics;
  std::function<void(std::uint32_t)> on_subscribe;  // set before clients connect
  Stats stats;
  bool flush_posted = false;
  bool retry_armed = false;
  std::unique_ptr<asio::steady_timer> retry;
  struct Periodic {
    std::uint32_t channel;
    std::chrono::milliseconds period;
    std::function<std::string()> make;
    std::unique_ptr<asio::steady_timer> timer;
  };
  std::vector<std::unique_ptr<Periodic>> periodic;  // touched on the server's thread only

  bool subscribedLocked(std::uint32_t channel) const {
    for (const auto& [h, c] : clients)
      for (const auto& [id, sub] : c.subscriptions)
        if (sub.channel + 1 == channel) return true;
    return false;
  }

  // The channel's newest message (keep-latest: replaces one no client has had yet).
  void store(std::uint32_t channel, std::uint64_t stamp_ns, std::string payload) {
    std::lock_guard<std::mutex> lock(mutex);
    if (channel == 0 || channel > channels.size())
      throw ServerError("viewer: publish on unknown channel " + std::to_string(channel));
    auto& ch = channels[channel - 1];
    ch.payload = std::make_shared<const std::string>(std::move(payload));
    ch.stamp_ns = stamp_ns;
    ++ch.version;
  }

  void arm(Periodic& p) {
    p.timer->expires_after(p.period);
    p.timer->async_wait([this, &p](const std::error_code& e) {
      if (e) return;  // cancelled: the server stops
      bool wanted;
      {
        std::lock_guard<std::mutex> lock(mutex);
        wanted = subscribedLocked(p.channel);
      }
      if (wanted) {
        const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
        store(p.channel, static_cast<std::uint64_t>(now), p.make());
        flush();
      }
      arm(p);
    });
  }

  void fail(Hdl hdl, http_status::value code, const std::string& why) {
    auto con = server.get_con_from_hdl(hdl);
    con->set_status(code);
    con->set_body(why + "\n");
    con->replace_header("Content-Type", "text/plain; charset=utf-8");
    std::lock_guard<std::mutex> lock(mutex);
    ++stats.rejected;
  }

  // Token, Host and (for browsers) Origin: the checks every request passes. The page's script
  // and style sheet hold no data and are fetched without the page's query string, so they
  // need no token (`needs_token` false); the page and every WebSocket do.
  bool admitted(Hdl hdl, bool websocket, bool needs_token = true) {
    auto con = server.get_con_from_hdl(hdl);
    const std::string host = con->get_request_header("Host");
    if (host.empty()) {
      fail(hdl, http_status::bad_request, "a Host header is required");
      return false;
    }
    if (isLoopbackAddress(options.address)) {
      const std::string name = hostName(host);
      if (name != "127.0.0.1" && name != "localhost" && name != "[::1]") {
        fail(hdl, http_status::forbidden,
             "Host '" + host + "' refused: this server listens on loopback only");
        return false;
      }
    }
    if (needs_token && !options.token.empty()) {
      std::string given = queryValue(con->get_resource(), "token");
      const std::string auth = con->get_request_header("Authorization");
      if (given.empty() && auth.rfind("Bearer ", 0) == 0) given = auth.substr(7);
      if (!equalConstantTime(given, options.token)) {
        fail(hdl, http_status::unauthorized, "a valid token is required (?token=...)");
        return false;
      }
    }
    if (websocket) {
      const std::string origin = con->get_request_header("Origin");
      if (!origin.empty() && origin != "http://" + host &&
          std::find(options.allowed_origins.begin(), options.allowed_origins.end(), origin) ==
              options.allowed_origins.end()) {
        fail(hdl, http_status::forbidden, "Origin '" + origin + "' is not allowed");
        return false;
      }
    }
    return true;
  }

  bool validate(Hdl hdl) {
    if (!admitted(hdl, true)) return false;
    auto con = server.get_con_from_hdl(hdl);
    const auto& protocols = con->get_requested_subprotocols();
    if (std::find(protocols.begin(), protocols.end(), kSubprotocol) == protocols.end()) {
      fail(hdl, http_status::bad_request,
           std::string("WebSocket subprotocol ") + kSubprotocol + " is required");
      return false;
    }
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (clients.size() >= options.max_clients) {
        ++stats.rejected;
        con->set_status(http_status::service_unavailable);
        return false;
      }
    }
    con->select_subprotocol(kSubprotocol);
    return true;
  }

  void serveHttp(Hdl hdl) {
    auto con = server.get_con_from_hdl(hdl);
    std::string path = con->get_resource();
    path = path.substr(0, path.find('?'));
    if (path == "/") path = "/index.html";
    const bool is_page = path.size() > 5 && path.compare(path.size() - 5, 5, ".html") == 0;
    if (!admitted(hdl, false, is_page || !bodies.count(path))) return;
    const auto it = bodies.find(path);
    if (con->get_request().get_method() != "GET" || it == bodies.end()) {
      fail(hdl, http_status::not_found, "not found");
      return;
    }
    con->set_status(http_status::ok);
    con->set_body(std::string(it->second));
    con->replace_header("Content-Type", content_types[path]);
    con->replace_header("Cache-Control", "no-store");
    con->replace_header("X-Content-Type-Options", "nosniff");
    con->replace_header("Content-Security-Policy",
                        "default-src 'self'; connect-src 'self'; img-src 'self' data:");
  }

  void sendText(Hdl hdl, const json& j) {
    websocketpp::lib::error_code ec;
    const std::string text = j.dump();
    server.send(hdl, text, websocketpp::frame::opcode::text, ec);
  }

  void status(Hdl hdl, int level, const std::string& message) {
    sendText(hdl, {{"op", "status"}, {"level", level}, {"message", message}});
  }

  json channelJson(std::uint32_t id, const ChannelSpec& s) const {
    return {{"id", id},
            {"topic", s.topic},
            {"encoding", s.encoding},
            {"schemaName", s.schema_name},
            {"schema", s.schema},
            {"schemaEncoding", s.schema_encoding}};
  }

  void opened(Hdl hdl) {
    json info = {{"op", "serverInfo"},
                 {"name", options.name},
                 {"capabilities", json::array({"clientPublish"})},
                 {"supportedEncodings", json::array({"json"})},
                 {"metadata", json::object()},
                 {"sessionId", session_id}};
    json channels_json = json::array();
    {
      std::lock_guard<std::mutex> lock(mutex);
      clients[hdl];
      ++stats.clients_total;
      for (std::uint32_t i = 0; i < channels.size(); ++i)
        channels_json.push_back(channelJson(i + 1, channels[i].spec));
    }
    sendText(hdl, info);
    if (!channels_json.empty()) sendText(hdl, {{"op", "advertise"}, {"channels", channels_json}});
  }

  void closed(Hdl hdl) {
    std::lock_guard<std::mutex> lock(mutex);
    clients.erase(hdl);
  }

  void protocolError(Hdl hdl, const std::string& message) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      ++stats.protocol_errors;
    }
    status(hdl, 2, message);
  }

  void onText(Hdl hdl, const std::string& text) {
    json j = json::parse(text, nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("op") || !j["op"].is_string()) {
      protocolError(hdl, "expected a JSON object with an \"op\" field");
      return;
    }
    const std::string op = j["op"];
    std::vector<std::string> errors;
    std::vector<std::uint32_t> empty;  // subscribed channels without a message yet
    std::function<void(std::uint32_t)> subscribed_empty;
    bool flush = false;
    {
      std::lock_guard<std::mutex> lock(mutex);
      subscribed_empty = on_subscribe;
      auto it = clients.find(hdl);
      if (it == clients.end()) return;
      Client& c = it->second;
      auto list = [&](const char* key) -> const json* {
        if (!j.contains(key) || !j[key].is_array()) {
          errors.push_back(op + ": \"" + key + "\" must be an array");
          return nullptr;
        }
        return &j[key];
      };
      if (op == "subscribe") {
        if (const json* subs = list("subscriptions"))
          for (const auto& s : *subs) {
            if (!s.is_object() || !s.contains("id") || !s.contains("channelId") ||
                !s["id"].is_number_unsigned() || !s["channelId"].is_number_unsigned()) {
              errors.push_back("subscribe: each subscription needs unsigned id and channelId");
              continue;
            }
            const std::uint64_t channel = s["channelId"];
            const std::uint64_t id = s["id"];
            if (channel == 0 || channel > channels.size()) {
              errors.push_back("subscribe: unknown channel " + std::to_string(channel));
              continue;
            }
            if (id > 0xffffffffu || c.subscriptions.count(static_cast<std::uint32_t>(id))) {
              errors.push_back("subscribe: subscription id " + std::to_string(id) +
                               " is in use or too large");
              continue;
            }
            Subscription sub;
            sub.channel = static_cast<std::uint32_t>(channel - 1);
            const Channel& ch = channels[sub.channel];
            // The newest message goes out at once (maps are published rarely).
            sub.sent = ch.version > 0 ? ch.version - 1 : 0;
            if (ch.version == 0 && !ch.parts) empty.push_back(sub.channel + 1);
            c.subscriptions[static_cast<std::uint32_t>(id)] = sub;
            flush = true;
          }
      } else if (op == "unsubscribe") {
        if (const json* ids = list("subscriptionIds"))
          for (const auto& id : *ids)
            if (!id.is_number_unsigned() || !c.subscriptions.erase(id.get<std::uint32_t>()))
              errors.push_back("unsubscribe: unknown subscription " + id.dump());
      } else if (op == "advertise") {
        if (const json* chans = list("channels"))
          for (const auto& ch : *chans) {
            if (!ch.is_object() || !ch.contains("id") || !ch["id"].is_number_unsigned() ||
                !ch.contains("topic") || !ch["topic"].is_string()) {
              errors.push_back("advertise: each channel needs an unsigned id and a topic");
              continue;
            }
            const std::string topic = ch["topic"];
            if (!client_topics.count(topic)) {
              std::string accepted;
              for (const auto& [t, h] : client_topics)
                accepted += (accepted.empty() ? "" : ", ") + t;
              errors.push_back("advertise: topic '" + topic +
                               "' does not accept client messages (accepted: " +
                               (accepted.empty() ? "none" : accepted) + ")");
              continue;
            }
            c.advertised[ch["id"].get<std::uint32_t>()] = topic;
          }
      } else if (op == "unadvertise") {
        if (const json* ids = list("channelIds"))
          for (const auto& id : *ids)
            if (!id.is_number_unsigned() || !c.advertised.erase(id.get<std::uint32_t>()))
              errors.push_back("unadvertise: unknown client channel " + id.dump());
      } else {
        errors.push_back("unknown op '" + op + "'");
      }
      stats.protocol_errors += errors.size();
    }
    for (const auto& e : errors) status(hdl, 2, e);
    if (subscribed_empty)
      for (const std::uint32_t channel : empty) subscribed_empty(channel);
    if (flush) flushNow();
  }

  void onBinary(Hdl hdl, const std::string& data) {
    std::uint8_t opcode = 0;
    std::uint32_t channel = 0;
    if (!readLe(data, 0, opcode) || opcode != 1 || !readLe(data, 1, channel)) {
      protocolError(hdl, "binary messages must be client message data (opcode 1, channel id)");
      return;
    }
    ClientHandler handler;
    std::string topic;
    {
      std::lock_guard<std::mutex> lock(mutex);
      auto it = clients.find(hdl);
      if (it == clients.end()) return;
      auto ad = it->second.advertised.find(channel);
      if (ad != it->second.advertised.end()) {
        topic = ad->second;
        handler = client_topics[topic];
      }
    }
    if (!handler) {
      protocolError(hdl, "client channel " + std::to_string(channel) + " is not advertised");
      return;
    }
    const std::string error = handler(std::string_view(data).substr(5));
    if (!error.empty()) {
      protocolError(hdl, topic + ": " + error);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex);
    ++stats.client_messages;
  }

  // Called with the mutex held: is there room in this client's socket?
  bool hasRoom(const Server::connection_ptr& con) const {
    return con->get_buffered_amount() < options.max_buffered_kib * 1024;
  }

  void sendFrame(const Server::connection_ptr& con, std::uint32_t sub, std::uint64_t stamp,
                 const std::string& body_a, const std::string* body_b = nullptr) {
    std::string frame;
    frame.reserve(13 + body_a.size() + (body_b ? body_b->size() : 0));
    appendLe<std::uint8_t>(frame, 1);
    appendLe<std::uint32_t>(frame, sub);
    appendLe<std::uint64_t>(frame, stamp);
    frame += body_a;
    if (body_b) frame += *body_b;
    if (con->send(frame, websocketpp::frame::opcode::binary)) return;
    ++stats.messages_sent;
    stats.bytes_sent += frame.size();
  }

  // On the server's thread: each client gets what it has not seen, while it has room.
  void flush() {
    std::lock_guard<std::mutex> lock(mutex);
    flush_posted = false;
    bool blocked = false;
    for (auto& [hdl, client] : clients) {
      websocketpp::lib::error_code ec;
      auto con = server.get_con_from_hdl(hdl, ec);
      if (ec || con->get_state() != websocketpp::session::state::open) continue;
      for (auto& [id, sub] : client.subscriptions) {
        if (!hasRoom(con)) {
          blocked = true;
          break;
        }
        Channel& ch = channels[sub.channel];
        if (!ch.parts) {
          if (ch.version <= sub.sent || !ch.payload) continue;
          stats.drops += ch.version - sub.sent - 1;
          sendFrame(con, id, ch.stamp_ns, *ch.payload);
          sub.sent = ch.version;
          continue;
        }
        if (!ch.has_epoch) continue;
        const bool reset = !sub.has_epoch || sub.epoch != ch.epoch;
        if (!reset && ch.part_version <= sub.sent) continue;
        std::string body;
        appendLe<std::uint8_t>(body, reset ? 1 : 0);
        appendLe<std::uint32_t>(body, static_cast<std::uint32_t>(ch.header.size()));
        body += ch.header;
        std::string parts;
        std::uint32_t n = 0;
        for (const auto& [key, p] : ch.part)
          if (reset || p.first > sub.sent) {
            appendLe<std::uint32_t>(parts, static_cast<std::uint32_t>(p.second.size()));
            parts += p.second;
            ++n;
          }
        appendLe<std::uint32_t>(body, n);
        sendFrame(con, id, ch.stamp_ns, body, &parts);
        sub.sent = ch.part_version;
        sub.epoch = ch.epoch;
        sub.has_epoch = true;
      }
    }
    if (blocked && !retry_armed) {
      // Try again once the socket drained a little; nothing is queued meanwhile.
      retry_armed = true;
      retry->expires_after(std::chrono::milliseconds(20));
      retry->async_wait([this](const std::error_code& e) {
        {
          std::lock_guard<std::mutex> l(mutex);
          retry_armed = false;
        }
        if (!e) flush();
      });
    }
  }

  void flushNow() {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (flush_posted) return;
      flush_posted = true;
    }
    asio::post(server.get_io_service(), [this] { flush(); });
  }
};

FoxgloveServer::FoxgloveServer(FoxgloveServerOptions options, std::vector<StaticFile> files)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = std::move(options);
  for (auto& f : files) {
    m.bodies[f.path] = f.body;
    m.content_types[f.path] = f.content_type;
  }
  Server& s = m.server;
  s.clear_access_channels(websocketpp::log::alevel::all);
  s.clear_error_channels(websocketpp::log::elevel::all);
  websocketpp::lib::error_code ec;
  s.init_asio(ec);
  if (ec) throw ServerError("viewer: cannot start the network service: " + ec.message());
  s.set_reuse_addr(true);
  s.set_max_message_size(m.options.max_client_message_kib * 1024);
  s.set_max_http_body_size(64 * 1024);
  s.set_validate_handler([&m](Hdl h) { return m.validate(h); });
  s.set_http_handler([&m](Hdl h) { m.serveHttp(h); });
  s.set_open_handler([&m](Hdl h) { m.opened(h); });
  s.set_close_handler([&m](Hdl h) { m.closed(h); });
  s.set_message_handler([&m](Hdl h, Server::message_ptr msg) {
    if (msg->get_opcode() == websocketpp::frame::opcode::text)
      m.onText(h, msg->get_payload());
    else
      m.onBinary(h, msg->get_payload());
  });
  const std::string where = m.options.address + ":" + std::to_string(m.options.port);
  asio::error_code aec;
  const auto address = asio::ip::make_address(
      m.options.address == "localhost" ? std::string("127.0.0.1") : m.options.address, aec);
  if (aec)
    throw ServerError("viewer: address '" + m.options.address +
                      "' is not an IP address (e.g. 127.0.0.1, 0.0.0.0, ::1)");
  if (m.options.port < 0 || m.options.port > 65535)
    throw ServerError("viewer: port " + std::to_string(m.options.port) + " is not in 0..65535");
  s.listen(asio::ip::tcp::endpoint(address, static_cast<unsigned short>(m.options.port)), ec);
  if (ec) throw ServerError("viewer: cannot listen on " + where + ": " + ec.message());
  s.start_accept(ec);
  if (ec) throw ServerError("viewer: cannot accept on " + where + ": " + ec.message());
  m.bound_port = s.get_local_endpoint(ec).port();
  m.retry = std::make_unique<asio::steady_timer>(s.get_io_service());
  m.thread = std::thread([&s] {
    try {
      s.run();
    } catch (...) {
      // A handler threw: the server stops; the owner's stats show it no longer sends.
    }
  });
}

FoxgloveServer::~FoxgloveServer() {
  Impl& m = *impl_;
  asio::post(m.server.get_io_service(), [&m] {
    websocketpp::lib::error_code ec;
    m.server.stop_listening(ec);
    m.retry->cancel();
    for (auto& p : m.periodic) p->timer->cancel();
    std::vector<Hdl> open;
    {
      std::lock_guard<std::mutex> lock(m.mutex);
      for (auto& [h, c] : m.clients) open.push_back(h);
    }
    for (auto& h : open) m.server.close(h, websocketpp::close::status::going_away, "", ec);
  });
  // Give clients a moment to see the close frame, then stop regardless.
  for (int i = 0; i < 50; ++i) {
    {
      std::lock_guard<std::mutex> lock(m.mutex);
      if (m.clients.empty()) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  m.server.stop();
  if (m.thread.joinable()) m.thread.join();
}

int FoxgloveServer::port() const {
  return impl_->bound_port;
}

std::uint32_t FoxgloveServer::addChannel(ChannelSpec spec) {
  Impl& m = *impl_;
  std::uint32_t id;
  std::vector<Hdl> open;
  json channel;
  {
    std::lock_guard<std::mutex> lock(m.mutex);
    m.channels.push_back(Impl::Channel{});
    m.channels.back().spec = std::move(spec);
    id = static_cast<std::uint32_t>(m.channels.size());
    channel = m.channelJson(id, m.channels.back().spec);
    for (auto& [h, c] : m.clients) open.push_back(h);
  }
  if (!open.empty()) {
    const json ad = {{"op", "advertise"}, {"channels", json::array({channel})}};
    asio::post(m.server.get_io_service(), [&m, open, ad] {
      for (auto& h : open) m.sendText(h, ad);
    });
  }
  return id;
}

void FoxgloveServer::publish(std::uint32_t channel, std::uint64_t stamp_ns, std::string payload) {
  impl_->store(channel, stamp_ns, std::move(payload));
  impl_->flushNow();
}

void FoxgloveServer::publishParts(std::uint32_t channel, std::uint64_t stamp_ns,
                                  std::uint64_t epoch, std::string header,
                                  std::vector<std::pair<std::uint64_t, std::string>> parts) {
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mutex);
    if (channel == 0 || channel > m.channels.size())
      throw ServerError("viewer: publish on unknown channel " + std::to_string(channel));
    auto& ch = m.channels[channel - 1];
    ch.parts = true;
    if (!ch.has_epoch || ch.epoch != epoch) ch.part.clear();
    ch.has_epoch = true;
    ch.epoch = epoch;
    ch.header = std::move(header);
    ch.stamp_ns = stamp_ns;
    for (auto& [key, bytes] : parts) ch.part[key] = {++ch.part_version, std::move(bytes)};
  }
  m.flushNow();
}

void FoxgloveServer::acceptClientTopic(const std::string& topic, ClientHandler handler) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->client_topics[topic] = std::move(handler);
}

void FoxgloveServer::onSubscribe(std::function<void(std::uint32_t channel)> handler) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->on_subscribe = std::move(handler);
}

bool FoxgloveServer::subscribed(std::uint32_t channel) const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->subscribedLocked(channel);
}

void FoxgloveServer::publishEvery(std::uint32_t channel, int period_ms,
                                  std::function<std::string()> make) {
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mutex);
    if (channel == 0 || channel > m.channels.size())
      throw ServerError("viewer: publishEvery on unknown channel " + std::to_string(channel));
  }
  auto p = std::make_shared<std::unique_ptr<Impl::Periodic>>(new Impl::Periodic{
      channel, std::chrono::milliseconds(std::max(period_ms, 1)), std::move(make),
      std::make_unique<asio::steady_timer>(m.server.get_io_service())});
  asio::post(m.server.get_io_service(), [&m, p] {
    m.periodic.push_back(std::move(*p));
    m.arm(*m.periodic.back());
  });
}

FoxgloveServer::Stats FoxgloveServer::stats() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  Stats s = impl_->stats;
  s.clients = impl_->clients.size();
  return s;
}

}  // namespace tessera::viewer
