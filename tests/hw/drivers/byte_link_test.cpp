// ByteLink and PseudoTerminal: bytes both ways over a pty, the baud rate a driver sets, a
// device that is unplugged, and clear errors for devices that cannot be opened.
#include <tessera/drivers/byte_link.hpp>

#include <catch2/catch.hpp>

#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

namespace byte_link_test {

using namespace tessera::drivers;

std::string readMaster(int fd, std::size_t want) {
  std::string got;
  for (int tries = 0; tries < 100 && got.size() < want; ++tries) {
    pollfd p{fd, POLLIN, 0};
    ::poll(&p, 1, 10);
    char buf[256];
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n > 0) got.append(buf, static_cast<std::size_t>(n));
  }
  return got;
}

TEST_CASE("byte link talks to a pseudo-terminal at the baud rate it set", "[drivers][byte_link]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_byte_link_test";
  std::filesystem::create_directories(dir);
  PseudoTerminal pty((dir / "laser").string());
  CHECK(std::filesystem::is_symlink(pty.devicePath()));
  auto link = ByteLink::open(pty.devicePath(), 19200);
  CHECK(pty.slaveBaud() == 19200);
  link.writeAll("PP\n");
  CHECK(readMaster(pty.master(), 3) == "PP\n");
  REQUIRE(::write(pty.master(), "00P\n", 4) == 4);
  std::string in;
  for (int tries = 0; tries < 100 && in.size() < 4; ++tries) {
    link.readSome(in);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  CHECK(in == "00P\n");

  // Unplugged: the driver's side hangs up; plugged back in under the same link name.
  const std::string first = pty.slavePath();
  pty.close();
  std::string more;
  CHECK_THROWS_AS(link.readSome(more), LinkError);
  pty.reopen();
  CHECK(pty.slavePath() != first);
  auto again = ByteLink::open(pty.devicePath(), 115200);
  CHECK(pty.slaveBaud() == 115200);
}

TEST_CASE("byte link errors name the device and the reason", "[drivers][byte_link]") {
  CHECK_THROWS_WITH(
      ByteLink::open("/dev/tessera-no-such-port", 115200),
      Catch::Contains("/dev/tessera-no-such-port") && Catch::Contains("No such file"));
  CHECK_THROWS_WITH(ByteLink::open("", 115200), Catch::Contains("no device"));
  CHECK_THROWS_WITH(ByteLink::open("tcp://localhost", 115200), Catch::Contains("tcp://HOST:PORT"));
  CHECK_THROWS_WITH(ByteLink::open("tcp://localhost:x1", 115200),
                    Catch::Contains("is not a number"));
  CHECK_THROWS_WITH(ByteLink::open("/dev/null", 115200), Catch::Contains("not a terminal"));
  CHECK_THROWS_WITH(baudConstant(12345), Catch::Contains("12345"));
}

}  // namespace byte_link_test
