// Text from files and peers (grid and metadata names, library messages quoting them) made safe
// to print on one line of a log or a terminal: a name holding "\n[FAKE] ..." forged a log line,
// and escape sequences reached the terminal.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace isostream {

// `text` with control characters (C0, DEL, and C1 as UTF-8) and bytes that are not UTF-8
// written as \xNN, a backslash as \\, and what passes `max_bytes` of the result cut with "...".
// Valid UTF-8 otherwise prints as written.
std::string PrintableText(std::string_view text, size_t max_bytes = 1024);

}  // namespace isostream
