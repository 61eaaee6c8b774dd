// ByteLink: a device's byte stream, a serial port (termios, raw 8N1) or a TCP socket, opened
// non-blocking for a driver's poll loop; and PseudoTerminal, the other end an emulated device
// sits on (docs/architecture.md#device-drivers).
//
// Serial I/O is POSIX termios rather than libserialport: the drivers need raw 8N1 at a standard
// baud rate, a non-blocking descriptor they can poll next to a socket and a wake-up event, and
// nothing else; termios gives exactly that on serial ports, USB-ACM devices and the
// pseudo-terminals the tests use, without a dependency.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tessera::drivers {

/// Thrown when a link cannot be opened or used; what() names the device and the reason.
struct LinkError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class ByteLink {
 public:
  /// "tcp://HOST:PORT" or "HOST:PORT" with a numeric port opens a TCP connection (connect
  /// timeout `timeout_ms`); anything else is a serial device path opened at `baud`.
  static ByteLink open(const std::string& device, int baud, int timeout_ms = 1000);

  ByteLink() = default;
  ByteLink(ByteLink&& other) noexcept;
  ByteLink& operator=(ByteLink&& other) noexcept;
  ByteLink(const ByteLink&) = delete;
  ByteLink& operator=(const ByteLink&) = delete;
  ~ByteLink();

  int fd() const { return fd_; }
  bool isOpen() const { return fd_ >= 0; }
  const std::string& device() const { return device_; }

  /// Reads what is available (non-blocking) into `out`; returns the count, 0 when nothing is
  /// there. Throws LinkError when the device is gone (end of file, hang-up, I/O error).
  std::size_t readSome(std::string& out, std::size_t max_bytes = 65536);
  /// Writes all of `bytes`, waiting for the device at most `timeout_ms`; throws LinkError.
  void writeAll(std::string_view bytes, int timeout_ms = 200);
  void close();
  /// Serial ports: switches to `baud` (after the bytes written so far have gone out); sockets:
  /// nothing. Throws LinkError.
  void setBaud(int baud);

 private:
  ByteLink(int fd, std::string device, bool serial = false)
      : fd_(fd), device_(std::move(device)), serial_(serial) {}
  int fd_ = -1;
  std::string device_;
  bool serial_ = false;
};

/// The termios speed constant for `baud`; throws LinkError for a rate termios does not have.
unsigned baudConstant(int baud);

/// A pseudo-terminal pair: the emulator reads and writes `master()`, a driver opens
/// `slavePath()` (or `link`, a symlink to it that stays put across reopen(), like udev's
/// /dev/serial/by-id names). Master non-blocking; the slave end kept open here too, so that
/// the terminal and its settings live while the driver reconnects.
class PseudoTerminal {
 public:
  explicit PseudoTerminal(std::string link = "");
  ~PseudoTerminal();
  PseudoTerminal(const PseudoTerminal&) = delete;
  PseudoTerminal& operator=(const PseudoTerminal&) = delete;

  int master() const { return master_; }
  const std::string& slavePath() const { return slave_path_; }
  /// The path a driver should open: the symlink if one was asked for, else the slave.
  std::string devicePath() const { return link_.empty() ? slave_path_ : link_; }
  /// The baud rate the driver last set on the slave (0 if none of the standard ones).
  int slaveBaud() const;
  /// Unplugs the device: the driver's descriptor hangs up. reopen() plugs a new one in.
  void close();
  void reopen();

 private:
  void openPair();
  std::string link_;
  int master_ = -1, slave_ = -1;
  std::string slave_path_;
};

}  // namespace tessera::drivers
