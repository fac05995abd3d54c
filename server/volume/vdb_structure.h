// A check of an OpenVDB file's structure before OpenVDB reads it. Private to server/volume.
//
// OpenVDB trusts every count and length it reads: a damaged string length allocates up to 4 GB
// and fills it, a damaged metadata or root-node count loops for billions of failed reads (each
// failed string read then allocating from an uninitialised length), a damaged root child count
// allocates 256 KB per iteration until the process is killed, and a raw value chunk is read at
// the size its field claims into a buffer of the node's size (a heap overflow). One flipped byte
// in a catalogue's .vdb file would take isostreamd down while preparing it. This walks what
// OpenVDB parses (header, file and grid metadata, grid descriptors, transforms, and every float
// tree from its root to its leaves' values) and checks every count, length and chunk size
// against the bytes really there and the node it belongs to; and, since other trees are not
// walked, that OpenVDB cannot reach one while the loader reads a float grid.
#pragma once

#include <string>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

// OK if the structure of the file open as FD (read-only; read with pread, so its offset is left
// alone) is sound. Otherwise DataLoss naming the byte offset and what was wrong there,
// InvalidArgument for a file this loader will not read (not an OpenVDB file, a format version
// before 222, a float and a non-float grid of one name, a stream-written file of several grids
// or without a float grid), or ResourceExhausted for a float tree of more nodes than twice what
// a volume within LIMITS needs (OpenVDB would allocate them all before its active box could be
// checked). Messages start with PATH, the file's name. OpenVDB must be initialised (its
// metadata type registry is consulted).
absl::Status CheckVdbStructure(int fd, const std::string& path,
                               const VolumeLimits& limits = VolumeLimits{});

// The same for the file at PATH.
absl::Status CheckVdbStructure(const std::string& path,
                               const VolumeLimits& limits = VolumeLimits{});

}  // namespace isostream
