#include "udp_sender.hpp"

#include <netdb.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace detector {

UdpSender::~UdpSender() {
  if (fd_ >= 0) ::close(fd_);
}

Problem UdpSender::open(const Destination& destination) {
  name_ = destination.host + ":" + std::to_string(destination.port);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(destination.port);
  if (const int rc = ::getaddrinfo(destination.host.c_str(), port.c_str(), &hints, &found); rc != 0)
    return "--udp " + name_ + ": cannot resolve host \"" + destination.host + "\": " +
           ::gai_strerror(rc);
  // Prefer IPv4 when a name has both: "localhost" often resolves to ::1 first,
  // while the robot's UDP device listens on IPv4.
  const addrinfo* chosen = found;
  for (const addrinfo* a = found; a; a = a->ai_next) {
    if (a->ai_family == AF_INET) {
      chosen = a;
      break;
    }
  }
  fd_ = ::socket(chosen->ai_family, chosen->ai_socktype, chosen->ai_protocol);
  if (fd_ < 0) {
    const int err = errno;
    ::freeaddrinfo(found);
    return "--udp " + name_ + ": cannot create socket: " + std::strerror(err);
  }
  std::memcpy(&address_, chosen->ai_addr, chosen->ai_addrlen);
  address_length_ = chosen->ai_addrlen;
  ::freeaddrinfo(found);
  return std::nullopt;
}

Problem UdpSender::send(const std::string& payload) {
  const ssize_t sent = ::sendto(fd_, payload.data(), payload.size(), 0,
                                reinterpret_cast<const sockaddr*>(&address_), address_length_);
  if (sent >= 0 || failure_reported_) return std::nullopt;
  failure_reported_ = true;
  return "--udp " + name_ + ": send failed: " + std::strerror(errno) + " (reported once)";
}

}  // namespace detector
