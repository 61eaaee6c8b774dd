// Tests for the Foxglove WebSocket server: the protocol as a client sees it (serverInfo,
// advertise, subscribe, message data, client publish, parts channels), keep-latest delivery to
// a client that does not read, and the refusals: bad frames, oversized messages and requests,
// unknown channels, path traversal, tokens, Host and Origin checks, too many clients.
#include <tessera/viewer/foxglove_server.hpp>

#include "ws_test_client.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <atomic>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

// Everything in a namespace of its own: unity builds put test files together.
namespace foxglove_server_test {

using namespace tessera::viewer;
using namespace tessera::viewer::testing;
using nlohmann::json;

namespace {

const std::string kPage = "<html>tessera</html>";

FoxgloveServerOptions anyPort() {
  FoxgloveServerOptions o;
  o.port = 0;
  return o;
}

std::vector<StaticFile> page() {
  return {{"/index.html", "text/html", kPage}, {"/viewer.js", "text/javascript", "let x = 1;"}};
}

json readJson(WsClient& c, const std::string& op) {
  auto f = c.readUntil("\"op\":\"" + op + "\"");
  REQUIRE(f);
  REQUIRE(f->opcode == 1);
  return json::parse(f->payload);
}

std::uint32_t channelId(const json& advertise, const std::string& topic) {
  for (const auto& ch : advertise["channels"])
    if (ch["topic"] == topic) return ch["id"];
  FAIL("no channel " << topic);
  return 0;
}

void subscribe(WsClient& c, std::uint32_t sub, std::uint32_t channel) {
  c.sendText(
      json{{"op", "subscribe"}, {"subscriptions", {{{"id", sub}, {"channelId", channel}}}}}.dump());
}

// The next message-data frame: subscription id, timestamp, payload.
struct Data {
  std::uint32_t sub;
  std::uint64_t stamp;
  std::string payload;
};
Data readData(WsClient& c) {
  auto f = c.readUntil("", 2);
  REQUIRE(f);
  REQUIRE(f->opcode == 2);
  REQUIRE(f->payload.size() >= 13);
  REQUIRE(f->payload[0] == 1);
  return {readLe<std::uint32_t>(f->payload, 1), readLe<std::uint64_t>(f->payload, 5),
          f->payload.substr(13)};
}

}  // namespace

TEST_CASE("the server hands out its page and nothing else", "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const int port = server.port();
  REQUIRE(port > 0);
  const std::string ok = httpGet(port, "/");
  CHECK(statusOf(ok) == 200);
  CHECK(ok.find(kPage) != std::string::npos);
  CHECK(ok.find("Content-Security-Policy") != std::string::npos);
  CHECK(statusOf(httpGet(port, "/index.html?x=1")) == 200);
  for (const char* bad : {"/../etc/passwd", "/..%2f..%2fetc%2fpasswd", "/%2e%2e/index.html",
                          "//etc/passwd", "/index.html/..", "/nothing.js"})
    CHECK(statusOf(httpGet(port, bad)) == 404);
  CHECK(server.stats().rejected >= 6);
}

TEST_CASE("oversized and malformed HTTP requests are refused and the server keeps serving",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const int port = server.port();
  {
    TestSocket s(port);
    s.write("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + std::string(200000, 'a') + "\r\n\r\n");
    const std::string r = s.readResponse();
    CHECK((r.empty() || statusOf(r) >= 400));
    CHECK_FALSE(s.timedOut());
  }
  {
    TestSocket s(port);
    s.write("\x16\x03\x01 garbage that is not HTTP\r\n\r\n");
    const std::string r = s.readResponse();
    CHECK((r.empty() || statusOf(r) >= 400));
    CHECK_FALSE(s.timedOut());
  }
  {
    TestSocket s(port);
    s.write("GET / HTTP/1.1\r\n\r\n");  // no Host
    CHECK(statusOf(s.readResponse()) == 400);
  }
  CHECK(statusOf(httpGet(port, "/")) == 200);
}

TEST_CASE("a client is told the server's channels and gets what it subscribes to",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const auto map = server.addChannel({"map", "json", "foxglove.Grid", "{}", "jsonschema"});
  const auto scan = server.addChannel({"scan", "json", "foxglove.LaserScan", "{}", "jsonschema"});
  server.publish(map, 5, R"({"m":1})");  // before anyone connects: the newest goes out later

  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  CHECK(c.head().find("Sec-WebSocket-Protocol: foxglove.websocket.v1") != std::string::npos);
  const json info = readJson(c, "serverInfo");
  CHECK(info["name"] == "tessera");
  CHECK(info["capabilities"] == json::array({"clientPublish"}));
  {
    WsClient again(server.port());  // the session id names the server, not the connection
    CHECK(readJson(again, "serverInfo")["sessionId"] == info["sessionId"]);
  }
  const json ad = readJson(c, "advertise");
  REQUIRE(ad["channels"].size() == 2);
  CHECK(ad["channels"][1]["schemaName"] == "foxglove.LaserScan");
  CHECK(channelId(ad, "map") == map);

  subscribe(c, 7, map);
  Data d = readData(c);
  CHECK(d.sub == 7);
  CHECK(d.stamp == 5);
  CHECK(d.payload == R"({"m":1})");
  CHECK_FALSE(server.subscribed(scan));
  CHECK(server.subscribed(map));

  // A channel added later is advertised to connected clients.
  const auto late = server.addChannel({"path", "json", "foxglove.PosesInFrame", "", ""});
  const json ad2 = readJson(c, "advertise");
  CHECK(channelId(ad2, "path") == late);

  subscribe(c, 8, scan);
  server.publish(scan, 9, "s1");
  d = readData(c);
  CHECK(d.sub == 8);
  CHECK(d.payload == "s1");

  c.sendText(R"({"op":"unsubscribe","subscriptionIds":[8]})");
  server.publish(map, 10, "m2");
  d = readData(c);  // scan is unsubscribed: the next data is the map's
  CHECK(d.sub == 7);
  CHECK(d.payload == "m2");
  CHECK(server.stats().clients == 1);
}

TEST_CASE("bad client messages get an error status and the connection stays usable",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const auto ch = server.addChannel({"map", "json", "", "", ""});
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "advertise");
  for (const std::string& bad :
       {std::string("not json"), std::string("[1,2]"), std::string(R"({"op":"launch"})"),
        std::string(R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]})"),
        std::string(R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":"x"}]})"),
        std::string(R"({"op":"subscribe","subscriptions":7})"),
        std::string(R"({"op":"unsubscribe","subscriptionIds":[42]})"),
        std::string(R"({"op":"advertise","channels":[{"id":1,"topic":"cmd_vel"}]})")}) {
    c.sendText(bad);
    const json st = readJson(c, "status");
    CHECK(st["level"] == 2);
    INFO(bad << " -> " << st["message"]);
    CHECK_FALSE(st["message"].get<std::string>().empty());
  }
  c.send(2, std::string("\x07\x00\x00\x00\x00", 5));  // an unknown binary opcode
  CHECK(readJson(c, "status")["level"] == 2);
  c.send(2, std::string("\x01\x09\x00\x00\x00{}", 7));  // data on a channel never advertised
  CHECK(readJson(c, "status")["message"].get<std::string>().find("not advertised") !=
        std::string::npos);
  CHECK(server.stats().protocol_errors >= 10);
  // Still subscribed-to and served.
  subscribe(c, 1, ch);
  server.publish(ch, 1, "ok");
  CHECK(readData(c).payload == "ok");
}

TEST_CASE("malformed WebSocket frames and oversized messages close only that connection",
          "[viewer][server]") {
  FoxgloveServerOptions o = anyPort();
  o.max_client_message_kib = 4;
  FoxgloveServer server(o, page());
  const int port = server.port();
  SECTION("unmasked client frame") {
    WsClient c(port);
    REQUIRE(c.status() == 101);
    c.sendRaw(encodeFrame(1, R"({"op":"subscribe"})", /*mask=*/false));
    CHECK(c.closedByServer());
  }
  SECTION("reserved bits set") {
    WsClient c(port);
    REQUIRE(c.status() == 101);
    c.sendRaw(encodeFrame(1, "{}", true, /*rsv=*/3));
    CHECK(c.closedByServer());
  }
  SECTION("a message above the limit") {
    WsClient c(port);
    REQUIRE(c.status() == 101);
    c.sendText(std::string(8 * 1024, ' '));
    auto f = c.readUntil("never", 1);
    REQUIRE(f);
    CHECK(f->opcode == 8);
    CHECK(readLe<std::uint8_t>(f->payload, 0) * 256 + readLe<std::uint8_t>(f->payload, 1) ==
          1009);  // message too big
  }
  SECTION("a frame cut short") {
    {
      WsClient c(port);
      REQUIRE(c.status() == 101);
      c.sendRaw(encodeFrame(1, std::string(1000, 'x')).substr(0, 100));
    }  // the client goes away mid-frame
  }
  // Others are unaffected.
  WsClient other(port);
  CHECK(other.status() == 101);
  CHECK(statusOf(httpGet(port, "/")) == 200);
}

TEST_CASE("a handshake needs the Foxglove subprotocol, a loopback Host, an allowed Origin",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const int port = server.port();
  CHECK(WsClient(port, "/", "", "").status() == 400);
  CHECK(WsClient(port, "/", "", "chat").status() == 400);
  CHECK(WsClient(port, "/", "", "foxglove.websocket.v1", "attacker.example").status() == 403);
  CHECK(statusOf(httpGet(port, "/", "", "attacker.example")) == 403);
  CHECK(WsClient(port, "/", "Origin: http://attacker.example\r\n").status() == 403);
  CHECK(WsClient(port, "/", "Origin: http://127.0.0.1:" + std::to_string(port) + "\r\n").status() ==
        101);
  CHECK(WsClient(port, "/", "Origin: https://app.foxglove.dev\r\n").status() == 101);
  CHECK(WsClient(port, "/", "", "foxglove.websocket.v1", "localhost").status() == 101);
}

TEST_CASE("a token is required on every request when set", "[viewer][server]") {
  FoxgloveServerOptions o = anyPort();
  o.token = "s3cret";
  FoxgloveServer server(o, page());
  const int port = server.port();
  CHECK(statusOf(httpGet(port, "/")) == 401);
  CHECK(statusOf(httpGet(port, "/?token=wrong")) == 401);
  CHECK(statusOf(httpGet(port, "/?token=s3cre")) == 401);
  CHECK(statusOf(httpGet(port, "/?token=s3cret")) == 200);
  CHECK(statusOf(httpGet(port, "/", "Authorization: Bearer s3cret\r\n")) == 200);
  // The page's script holds no data and is fetched without the page's query: no token needed;
  // anything else unknown still asks for one.
  CHECK(statusOf(httpGet(port, "/viewer.js")) == 200);
  CHECK(statusOf(httpGet(port, "/secret.txt")) == 401);
  CHECK(WsClient(port, "/").status() == 401);
  CHECK(WsClient(port, "/?token=s3cret").status() == 101);
}

TEST_CASE("clients beyond max_clients are refused", "[viewer][server]") {
  FoxgloveServerOptions o = anyPort();
  o.max_clients = 2;
  FoxgloveServer server(o, page());
  WsClient a(server.port()), b(server.port());
  REQUIRE(a.status() == 101);
  REQUIRE(b.status() == 101);
  readJson(a, "serverInfo");
  readJson(b, "serverInfo");
  CHECK(WsClient(server.port()).status() == 503);
}

TEST_CASE("clients publish only on accepted topics, and handler errors come back",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  std::mutex m;
  std::vector<std::string> got;
  server.acceptClientTopic("goal", [&](std::string_view payload) -> std::string {
    if (payload == "bad") return "cannot read a pose";
    std::lock_guard<std::mutex> lock(m);
    got.emplace_back(payload);
    return "";
  });
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "serverInfo");
  c.sendText(R"({"op":"advertise","channels":[{"id":3,"topic":"goal","encoding":"json"}]})");
  c.send(2, std::string("\x01\x03\x00\x00\x00", 5) + R"({"x":1,"y":2})");
  c.send(2, std::string("\x01\x03\x00\x00\x00", 5) + "bad");
  const json st = readJson(c, "status");
  CHECK(st["message"] == "goal: cannot read a pose");
  {
    std::lock_guard<std::mutex> lock(m);
    REQUIRE(got.size() == 1);
    CHECK(got[0] == R"({"x":1,"y":2})");
  }
  CHECK(server.stats().client_messages == 1);
  c.sendText(R"({"op":"unadvertise","channelIds":[3]})");
  c.send(2, std::string("\x01\x03\x00\x00\x00", 5) + R"({"x":1,"y":2})");
  CHECK(readJson(c, "status")["message"].get<std::string>().find("not advertised") !=
        std::string::npos);
}

TEST_CASE("a parts channel sends a new client everything and then only what changed",
          "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const auto tiles = server.addChannel({"map/tiles", "tessera.tiles", "", "", ""});
  server.publishParts(tiles, 1, 1, "H1", {{1, "aa"}, {2, "bb"}});
  server.publishParts(tiles, 2, 1, "H2", {{2, "BB"}, {3, "cc"}});
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "advertise");
  subscribe(c, 1, tiles);
  auto parse = [](const std::string& p) {
    std::vector<std::string> parts;
    const std::uint32_t hl = readLe<std::uint32_t>(p, 1);
    std::size_t at = 5 + hl;
    const std::uint32_t n = readLe<std::uint32_t>(p, at);
    at += 4;
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::uint32_t len = readLe<std::uint32_t>(p, at);
      parts.push_back(p.substr(at + 4, len));
      at += 4 + len;
    }
    return std::make_tuple(static_cast<int>(p[0]), p.substr(5, hl), parts);
  };
  auto [reset, header, parts] = parse(readData(c).payload);
  CHECK(reset == 1);
  CHECK(header == "H2");
  CHECK(parts == std::vector<std::string>{"aa", "BB", "cc"});
  server.publishParts(tiles, 3, 1, "H3", {{3, "CC"}});
  std::tie(reset, header, parts) = parse(readData(c).payload);
  CHECK(reset == 0);
  CHECK(header == "H3");
  CHECK(parts == std::vector<std::string>{"CC"});
  server.publishParts(tiles, 4, 2, "H4", {{9, "zz"}});  // a new epoch forgets the rest
  std::tie(reset, header, parts) = parse(readData(c).payload);
  CHECK(reset == 1);
  CHECK(parts == std::vector<std::string>{"zz"});
}

TEST_CASE("a client that stops reading gets the newest message later, the rest counted as drops",
          "[viewer][server]") {
  FoxgloveServerOptions o = anyPort();
  o.max_buffered_kib = 64;
  FoxgloveServer server(o, page());
  const auto ch = server.addChannel({"scan", "json", "", "", ""});
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "advertise");
  subscribe(c, 1, ch);
  // Wait for the subscription to be in place.
  for (int i = 0; i < 200 && !server.subscribed(ch); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  REQUIRE(server.subscribed(ch));
  // 400 x 256 KB = 100 MB while the client reads nothing: far more than the socket holds.
  const int n = 400;
  for (int i = 1; i <= n; ++i) {
    std::string body(256 * 1024, 'x');
    body.replace(0, 8, std::to_string(100000000 + i));
    server.publish(ch, static_cast<std::uint64_t>(i), body);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  CHECK(server.stats().bytes_sent < 40ull * 1024 * 1024);  // what the socket took, not 100 MB
  // Now read: the last message arrives; stamps only increase.
  std::uint64_t last = 0;
  for (;;) {
    Data d = readData(c);
    CHECK(d.stamp > last);
    last = d.stamp;
    if (d.stamp == static_cast<std::uint64_t>(n)) break;
  }
  CHECK(last == static_cast<std::uint64_t>(n));
  // Drops are counted when a newer message goes out in their place: by now every message was
  // either sent or replaced. (Counted before the client reads, they depended on how the
  // publishing and the server's threads happened to interleave: a test bug fixed.)
  const auto stats = server.stats();
  CHECK(stats.drops > 0);
  CHECK(stats.messages_sent + stats.drops == static_cast<std::uint64_t>(n));
}

TEST_CASE("the server names what it cannot bind", "[viewer][server]") {
  FoxgloveServer first(anyPort(), page());
  FoxgloveServerOptions o;
  o.port = first.port();
  o.address = "127.0.0.1";
  // Same port, same address: in use (SO_REUSEADDR does not allow two listeners).
  CHECK_THROWS_WITH(FoxgloveServer(o, page()),
                    Catch::Contains("127.0.0.1:" + std::to_string(first.port())));
  o.address = "not-an-address";
  CHECK_THROWS_WITH(FoxgloveServer(o, page()), Catch::Contains("not an IP address"));
  o.address = "127.0.0.1";
  o.port = 70000;
  CHECK_THROWS_WITH(FoxgloveServer(o, page()), Catch::Contains("0..65535"));
}

TEST_CASE("periodic figures are made only while someone subscribes", "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const auto ch = server.addChannel({"tessera/metrics", "json", "", "", ""});
  std::atomic<int> made{0};
  server.publishEvery(ch, 10, [&] { return "{\"n\":" + std::to_string(++made) + "}"; });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  CHECK(made == 0);  // nobody looks
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "advertise");
  subscribe(c, 1, ch);
  const Data a = readData(c);
  const Data b = readData(c);
  CHECK(a.payload != b.payload);
  CHECK(b.stamp >= a.stamp);
  CHECK(made >= 2);
}

TEST_CASE("a first subscription to a channel without a message asks for one", "[viewer][server]") {
  FoxgloveServer server(anyPort(), page());
  const auto held = server.addChannel({"landmark_map", "json", "", "", ""});
  const auto sent = server.addChannel({"map", "json", "", "", ""});
  server.publish(sent, 1, "m");
  std::mutex m;
  std::vector<std::uint32_t> asked;
  server.onSubscribe([&](std::uint32_t channel) {
    {
      std::lock_guard<std::mutex> lock(m);
      asked.push_back(channel);
    }
    server.publish(channel, 2, "held back");  // what a publisher that kept it would do
  });
  WsClient c(server.port());
  REQUIRE(c.status() == 101);
  readJson(c, "advertise");
  subscribe(c, 1, sent);  // has a message: no question
  CHECK(readData(c).payload == "m");
  subscribe(c, 2, held);
  const Data d = readData(c);
  CHECK(d.sub == 2);
  CHECK(d.payload == "held back");
  std::lock_guard<std::mutex> lock(m);
  CHECK(asked == std::vector<std::uint32_t>{held});
}

}  // namespace foxglove_server_test
