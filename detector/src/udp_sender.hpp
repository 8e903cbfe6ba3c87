// Sends each datagram to the robot (SPEC §7: the toroco_udp_camera device).
// Fire and forget: a lost or refused datagram is superseded by the next frame's.
#pragma once

#include <sys/socket.h>

#include <string>

#include "options.hpp"

namespace detector {

class UdpSender {
 public:
  UdpSender() = default;
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;
  ~UdpSender();

  // Resolves the host and makes the socket; a problem names the destination.
  Problem open(const Destination& destination);

  // Returns the problem of the first failed send only, so a robot that is not
  // listening yet is reported once rather than on every frame.
  Problem send(const std::string& payload);

 private:
  int fd_ = -1;
  std::string name_;
  sockaddr_storage address_{};
  socklen_t address_length_ = 0;
  bool failure_reported_ = false;
};

}  // namespace detector
