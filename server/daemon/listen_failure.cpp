#include "server/daemon/listen_failure.h"

#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace isostream::daemon {

std::string ListenFailureReason(const std::string& address) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos) return "";
  std::string host = address.substr(0, colon);
  const std::string port = address.substr(colon + 1);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.empty() ? nullptr : host.c_str(), port.c_str(), &hints, &found) != 0)
    return "the host name does not resolve";
  std::string reason;
  const int fd = socket(found->ai_family, found->ai_socktype, found->ai_protocol);
  if (fd >= 0) {
    const int on = 1;  // as gRPC binds: a port left in TIME_WAIT is free
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));
    if (bind(fd, found->ai_addr, found->ai_addrlen) != 0) {
      switch (errno) {
        case EADDRINUSE:
          reason = "the port is in use";
          break;
        case EADDRNOTAVAIL:
          reason = "the address is not this machine's";
          break;
        case EACCES:
          reason = "ports below 1024 need privileges (CAP_NET_BIND_SERVICE)";
          break;
        default:
          reason = std::strerror(errno);
      }
    }
    close(fd);
  }
  freeaddrinfo(found);
  return reason;
}

}  // namespace isostream::daemon
