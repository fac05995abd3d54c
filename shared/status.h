// Status at module edges: loaders, codecs and RPC handlers return absl::Status or
// absl::StatusOr<T>; exceptions from libraries (OpenVDB, zlib wrappers) are caught at the
// edge and turned into a status whose message names the input and the problem.
#pragma once

#include <absl/status/status.h>
#include <absl/status/statusor.h>

#define ISOSTREAM_RETURN_IF_ERROR(expr)                    \
  do {                                                     \
    ::absl::Status isostream_status_ = (expr);             \
    if (!isostream_status_.ok()) return isostream_status_; \
  } while (0)

#define ISOSTREAM_CONCAT_INNER(a, b) a##b
#define ISOSTREAM_CONCAT(a, b) ISOSTREAM_CONCAT_INNER(a, b)
#define ISOSTREAM_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                                    \
  if (!tmp.ok()) return tmp.status();                   \
  lhs = std::move(tmp).value()
#define ISOSTREAM_ASSIGN_OR_RETURN(lhs, expr) \
  ISOSTREAM_ASSIGN_OR_RETURN_IMPL(ISOSTREAM_CONCAT(isostream_statusor_, __LINE__), lhs, expr)
