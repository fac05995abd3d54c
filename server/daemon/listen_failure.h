// Why isostreamd could not listen on an address: gRPC's failure names no cause the daemon can
// read, so the address is bound once more here, by hand, and the system's answer told.
#pragma once

#include <string>

namespace isostream::daemon {

// "the port is in use", "the address is not this machine's", ...; "" when a bind by hand works
// (then something else failed: gRPC refused the TLS files, say).
std::string ListenFailureReason(const std::string& address);

}  // namespace isostream::daemon
