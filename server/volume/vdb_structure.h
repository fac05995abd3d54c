// A check of an OpenVDB file's framing before OpenVDB reads it. Private to server/volume.
//
// OpenVDB trusts every count and length it reads: a damaged string length allocates up to 4 GB
// and fills it, a damaged metadata or root-node count loops for billions of failed reads (each
// failed string read then allocates from an uninitialised length), and a damaged root child
// count allocates 256 KB per iteration until the process is killed. One flipped byte in a
// catalogue's .vdb file would take isostreamd down while preparing it. This walks the parts of
// the file OpenVDB parses before the voxel data (header, file and grid metadata, grid
// descriptors, transforms, the float trees' root counts) and checks every count and length
// against the bytes that are really there; what lies below the root is sized by fixed node
// masks, so damage there costs at most a bounded amount before OpenVDB's own reads fail.
#pragma once

#include <string>

#include "shared/status.h"

namespace isostream {

// OK if the framing is sound. Otherwise DataLoss naming the byte offset and what was wrong
// there, InvalidArgument for a well-formed file this loader cannot read (an unsupported format
// version, a frustum transform). Messages start with PATH. OpenVDB must be initialised (its
// metadata type registry is consulted).
absl::Status CheckVdbStructure(const std::string& path);

}  // namespace isostream
