// A deliberately small HTTP / WebSocket client for the viewer's server tests: plain POSIX
// sockets, so a test can send exactly the bytes it wants (bad frames, huge requests, wrong
// headers) and read what comes back. Not for use outside tests.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::viewer::testing {

class TestSocket {
 public:
  explicit TestSocket(int port, int timeout_ms = 3000) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd_ < 0) throw std::runtime_error("socket");
    timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
      throw std::runtime_error("connect to 127.0.0.1:" + std::to_string(port) + " failed");
  }
  ~TestSocket() {
    if (fd_ >= 0) ::close(fd_);
  }
  TestSocket(const TestSocket&) = delete;
  TestSocket& operator=(const TestSocket&) = delete;

  void write(const std::string& bytes) {
    std::size_t at = 0;
    while (at < bytes.size()) {
      const auto n = ::send(fd_, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL);
      if (n <= 0) return;  // the server closed: reads will show it
      at += static_cast<std::size_t>(n);
    }
  }
  /// Up to `n` bytes into buffer_ (false: timeout or closed).
  bool fill(std::size_t n) {
    while (buffer_.size() < n) {
      char chunk[65536];
      const auto got = ::recv(fd_, chunk, sizeof chunk, 0);
      if (got < 0) timed_out_ = true;
      if (got <= 0) return false;
      buffer_.append(chunk, static_cast<std::size_t>(got));
    }
    return true;
  }
  /// An HTTP response's head (through the blank line), or "" on timeout/close.
  std::string readHead() {
    for (;;) {
      const auto end = buffer_.find("\r\n\r\n");
      if (end != std::string::npos) {
        std::string head = buffer_.substr(0, end + 4);
        buffer_.erase(0, end + 4);
        return head;
      }
      if (!fill(buffer_.size() + 1)) return "";
    }
  }
  /// A whole HTTP response (head + body by Content-Length).
  std::string readResponse() {
    std::string head = readHead();
    if (head.empty()) return "";
    std::size_t length = 0;
    const auto cl = head.find("Content-Length: ");
    if (cl != std::string::npos) length = std::stoul(head.substr(cl + 16));
    fill(length);
    std::string body = buffer_.substr(0, std::min(length, buffer_.size()));
    buffer_.erase(0, body.size());
    return head + body;
  }
  std::string& buffer() { return buffer_; }
  /// Whether a read ended by the timeout (rather than the peer closing).
  bool timedOut() const { return timed_out_; }
  void closeWrite() { ::shutdown(fd_, SHUT_WR); }

 private:
  int fd_ = -1;
  bool timed_out_ = false;
  std::string buffer_;
};

inline int statusOf(const std::string& response) {
  if (response.rfind("HTTP/1.1 ", 0) != 0) return -1;
  return std::stoi(response.substr(9, 3));
}

struct Frame {
  int opcode = 0;
  std::string payload;
};

/// One frame as a client sends it (masked unless told otherwise).
inline std::string encodeFrame(int opcode, const std::string& payload, bool mask = true,
                               std::uint8_t rsv = 0) {
  std::string f;
  f.push_back(static_cast<char>(0x80 | (rsv << 4) | opcode));
  const std::uint8_t m = mask ? 0x80 : 0;
  if (payload.size() < 126) {
    f.push_back(static_cast<char>(m | payload.size()));
  } else if (payload.size() < 65536) {
    f.push_back(static_cast<char>(m | 126));
    f.push_back(static_cast<char>(payload.size() >> 8));
    f.push_back(static_cast<char>(payload.size() & 0xff));
  } else {
    f.push_back(static_cast<char>(m | 127));
    for (int i = 7; i >= 0; --i) f.push_back(static_cast<char>((payload.size() >> (8 * i)) & 0xff));
  }
  const char key[4] = {0x12, 0x34, 0x56, 0x78};
  if (mask) f.append(key, 4);
  for (std::size_t i = 0; i < payload.size(); ++i)
    f.push_back(mask ? static_cast<char>(payload[i] ^ key[i % 4]) : payload[i]);
  return f;
}

class WsClient {
 public:
  /// Connects and performs the handshake; `status()` tells how it went (101 = open).
  explicit WsClient(int port, const std::string& resource = "/",
                    const std::string& extra_headers = "",
                    const std::string& subprotocol = "foxglove.websocket.v1",
                    const std::string& host = "127.0.0.1")
      : socket_(port) {
    std::string req = "GET " + resource + " HTTP/1.1\r\nHost: " + host + ":" +
                      std::to_string(port) +
                      "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                      "Sec-WebSocket-Version: 13\r\n";
    if (!subprotocol.empty()) req += "Sec-WebSocket-Protocol: " + subprotocol + "\r\n";
    req += extra_headers + "\r\n";
    socket_.write(req);
    head_ = socket_.readHead();
    status_ = statusOf(head_);
  }
  int status() const { return status_; }
  const std::string& head() const { return head_; }

  void send(int opcode, const std::string& payload) { socket_.write(encodeFrame(opcode, payload)); }
  void sendText(const std::string& text) { send(1, text); }
  void sendRaw(const std::string& bytes) { socket_.write(bytes); }
  /// Whether the server ended the connection: a close frame or the socket closed, not silence.
  bool closedByServer() {
    for (;;) {
      auto f = read();
      if (!f) return !socket_.timedOut();
      if (f->opcode == 8) return true;
    }
  }

  /// The next frame from the server (control frames included), or nothing on timeout/close.
  std::optional<Frame> read() {
    if (!socket_.fill(2)) return std::nullopt;
    const auto b0 = static_cast<std::uint8_t>(socket_.buffer()[0]);
    const auto b1 = static_cast<std::uint8_t>(socket_.buffer()[1]);
    std::size_t header = 2;
    std::uint64_t length = b1 & 0x7f;
    if (length == 126) {
      if (!socket_.fill(4)) return std::nullopt;
      length = (static_cast<std::uint8_t>(socket_.buffer()[2]) << 8) |
               static_cast<std::uint8_t>(socket_.buffer()[3]);
      header = 4;
    } else if (length == 127) {
      if (!socket_.fill(10)) return std::nullopt;
      length = 0;
      for (int i = 0; i < 8; ++i)
        length = (length << 8) | static_cast<std::uint8_t>(socket_.buffer()[2 + i]);
      header = 10;
    }
    if (!socket_.fill(header + length)) return std::nullopt;
    Frame f{b0 & 0x0f, socket_.buffer().substr(header, length)};
    socket_.buffer().erase(0, header + length);
    return f;
  }
  /// The next data frame whose text contains `needle` (or any data frame for ""), skipping others.
  std::optional<Frame> readUntil(const std::string& needle, int opcode = 1, int max_frames = 200) {
    for (int i = 0; i < max_frames; ++i) {
      auto f = read();
      if (!f) return std::nullopt;
      if (f->opcode == 8) return f;  // closed
      if (f->opcode == opcode && f->payload.find(needle) != std::string::npos) return f;
    }
    return std::nullopt;
  }

 private:
  TestSocket socket_;
  std::string head_;
  int status_ = -1;
};

/// A whole HTTP exchange on a fresh connection.
inline std::string httpGet(int port, const std::string& resource,
                           const std::string& extra_headers = "",
                           const std::string& host = "127.0.0.1") {
  TestSocket s(port);
  s.write("GET " + resource + " HTTP/1.1\r\nHost: " + host + ":" + std::to_string(port) + "\r\n" +
          extra_headers + "Connection: close\r\n\r\n");
  return s.readResponse();
}

template <class T>
T readLe(const std::string& s, std::size_t at) {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i)
    v |= static_cast<std::uint64_t>(static_cast<std::uint8_t>(s.at(at + i))) << (8 * i);
  T out;
  std::memcpy(&out, &v, sizeof(T));
  return out;
}

}  // namespace tessera::viewer::testing
