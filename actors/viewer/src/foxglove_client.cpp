// The Foxglove WebSocket client over websocketpp (C++17, like foxglove_server.cpp).
#include <tessera/viewer/foxglove_client.hpp>
#include <tessera/viewer/foxglove_server.hpp>  // ServerError

#include "little_endian.hpp"

#define ASIO_STANDALONE
#include <websocketpp/client.hpp>
#include <websocketpp/config/asio_no_tls_client.hpp>

#include <nlohmann/json.hpp>

#include <pthread.h>
#include <time.h>

#include <chrono>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

namespace tessera::viewer {

namespace {
using Client = websocketpp::client<websocketpp::config::asio_client>;
using nlohmann::json;
constexpr std::size_t kMaxQueued = 1024;

}  // namespace

struct FoxgloveClient::Impl {
  Client client;
  std::thread thread;
  websocketpp::connection_hdl hdl;
  std::string url;

  mutable std::mutex mutex;
  std::condition_variable cv;
  bool open = false, failed = false, closed = false, got_info = false, got_advertise = false;
  std::string error, name;
  std::vector<RemoteChannel> channels;
  std::map<std::uint32_t, std::uint32_t> subscriptions;  // subscription id -> channel id
  std::uint32_t next_subscription = 1;
  std::deque<RemoteMessage> queue;
  std::uint64_t dropped = 0;

  void onText(const std::string& text) {
    const json j = json::parse(text, nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("op")) return;
    std::lock_guard<std::mutex> lock(mutex);
    if (j["op"] == "serverInfo") {
      name = j.value("name", std::string());
      got_info = true;
    } else if (j["op"] == "advertise" && j.contains("channels") && j["channels"].is_array()) {
      for (const auto& c : j["channels"]) {
        if (!c.is_object()) continue;
        channels.push_back({c.value("id", 0u), c.value("topic", std::string()),
                            c.value("encoding", std::string()),
                            c.value("schemaName", std::string())});
      }
      got_advertise = true;
    }
    cv.notify_all();
  }

  void onBinary(const std::string& data) {
    std::uint32_t sub = 0;
    std::uint64_t stamp = 0;
    if (data.size() < 13 || data[0] != 1 || !detail::readLe(data, 1, sub) ||
        !detail::readLe(data, 5, stamp))
      return;
    std::lock_guard<std::mutex> lock(mutex);
    const auto it = subscriptions.find(sub);
    if (it == subscriptions.end()) return;
    if (queue.size() >= kMaxQueued) {
      queue.pop_front();
      ++dropped;
    }
    queue.push_back({it->second, stamp, data.substr(13)});
    cv.notify_all();
  }
};

FoxgloveClient::FoxgloveClient(const std::string& url, int timeout_ms)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.url = url;
  Client& c = m.client;
  c.clear_access_channels(websocketpp::log::alevel::all);
  c.clear_error_channels(websocketpp::log::elevel::all);
  websocketpp::lib::error_code ec;
  c.init_asio(ec);
  if (ec) throw ServerError("cannot start the network service: " + ec.message());
  c.set_open_handler([&m](websocketpp::connection_hdl) {
    std::lock_guard<std::mutex> lock(m.mutex);
    m.open = true;
    m.cv.notify_all();
  });
  c.set_fail_handler([&m](websocketpp::connection_hdl h) {
    auto con = m.client.get_con_from_hdl(h);
    std::string why;
    const int status = con->get_response_code();
    if (status == 401)
      why = "refused: the viewer wants a token (add ?token=TOKEN to the URL)";
    else if (status > 0)
      why = "refused with HTTP " + std::to_string(status) + ": " + con->get_response().get_body();
    else
      why = "nothing answers at " + m.url + " (" + con->get_ec().message() +
            "); is a run with --view PORT going?";
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    std::lock_guard<std::mutex> lock(m.mutex);
    m.failed = true;
    m.error = why;
    m.cv.notify_all();
  });
  c.set_close_handler([&m](websocketpp::connection_hdl) {
    std::lock_guard<std::mutex> lock(m.mutex);
    m.closed = true;
    m.cv.notify_all();
  });
  c.set_message_handler([&m](websocketpp::connection_hdl, Client::message_ptr msg) {
    if (msg->get_opcode() == websocketpp::frame::opcode::text)
      m.onText(msg->get_payload());
    else
      m.onBinary(msg->get_payload());
  });
  auto con = c.get_connection(url, ec);
  if (ec)
    throw ServerError("'" + url + "' is not a WebSocket URL (ws://HOST:PORT): " + ec.message());
  con->add_subprotocol("foxglove.websocket.v1");
  m.hdl = con->get_handle();
  c.connect(con);
  m.thread = std::thread([&c] {
    try {
      c.run();
    } catch (...) {
      // A handler threw: the client stops; next() then reports it closed.
    }
  });
  // The server sends serverInfo, then its channels at once; a server without channels sends
  // none, so after serverInfo the wait for them is short.
  std::unique_lock<std::mutex> lock(m.mutex);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  m.cv.wait_until(lock, deadline, [&m] { return m.got_info || m.failed || m.closed; });
  if (m.got_info)
    m.cv.wait_for(lock, std::chrono::milliseconds(300), [&m] { return m.got_advertise; });
  std::string error;
  if (m.failed)
    error = m.error;
  else if (!m.got_info)
    error = m.open ? "connected to " + url + ", but it does not speak foxglove.websocket.v1"
                   : "no answer from " + url + " within " + std::to_string(timeout_ms) + " ms";
  lock.unlock();
  if (!error.empty()) {
    c.stop();
    m.thread.join();
    throw ServerError(error);
  }
}

FoxgloveClient::~FoxgloveClient() {
  Impl& m = *impl_;
  asio::post(m.client.get_io_service(), [&m] {
    websocketpp::lib::error_code ec;
    m.client.close(m.hdl, websocketpp::close::status::normal, "", ec);
  });
  {
    std::unique_lock<std::mutex> lock(m.mutex);
    m.cv.wait_for(lock, std::chrono::milliseconds(500), [&m] { return m.closed; });
  }
  m.client.stop();
  if (m.thread.joinable()) m.thread.join();
}

std::string FoxgloveClient::serverName() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->name;
}

std::vector<RemoteChannel> FoxgloveClient::channels() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->channels;
}

void FoxgloveClient::subscribe(std::uint32_t channel) {
  Impl& m = *impl_;
  std::uint32_t id;
  {
    std::lock_guard<std::mutex> lock(m.mutex);
    id = m.next_subscription++;
    m.subscriptions[id] = channel;
  }
  const std::string text =
      json{{"op", "subscribe"}, {"subscriptions", {{{"id", id}, {"channelId", channel}}}}}.dump();
  asio::post(m.client.get_io_service(), [&m, text] {
    websocketpp::lib::error_code ec;
    m.client.send(m.hdl, text, websocketpp::frame::opcode::text, ec);
  });
}

std::optional<RemoteMessage> FoxgloveClient::next(int timeout_ms) {
  Impl& m = *impl_;
  std::unique_lock<std::mutex> lock(m.mutex);
  m.cv.wait_for(lock, std::chrono::milliseconds(timeout_ms),
                [&m] { return !m.queue.empty() || m.closed; });
  if (m.queue.empty()) return std::nullopt;
  RemoteMessage out = std::move(m.queue.front());
  m.queue.pop_front();
  return out;
}

bool FoxgloveClient::closed() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->closed;
}

std::uint64_t FoxgloveClient::dropped() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->dropped;
}

}  // namespace tessera::viewer

namespace tessera::viewer {

double FoxgloveClient::networkCpuSeconds() const {
  clockid_t clock;
  if (pthread_getcpuclockid(impl_->thread.native_handle(), &clock) != 0) return 0;
  timespec ts{};
  if (clock_gettime(clock, &ts) != 0) return 0;
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

}  // namespace tessera::viewer
