// The structure check of OpenVDB files (vdb_structure.h). It follows OpenVDB 10's own read
// order (io::Archive::readHeader, MetaMap::readMeta, GridDescriptor::read, Archive::readGrid,
// Transform::read, the Root/Internal/LeafNode readTopology and readBuffers,
// io::readCompressedValues) for file versions 222-224, little-endian as written on x86 and ARM.
#include "server/volume/vdb_structure.h"

#include <fcntl.h>
#include <openvdb/Metadata.h>
#include <openvdb/openvdb.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "absl/strings/strip.h"

namespace isostream {
namespace {

// Whatever went wrong, at which byte; `unsupported` for a sound file this loader cannot read,
// `too_big` for one whose tree would need more memory than the limits allow.
struct Defect {
  int64_t at = 0;
  std::string what;
  bool unsupported = false;
  bool too_big = false;
};

// The memory one float tree's nodes may take: twice what a volume within the limits can need
// (the slack is for inactive nodes beside it). Its active box, d0 x d1 x d2 with every side at
// most max_dim and at most max_voxels in all, meets at most ceil(d / w) + 1 nodes of width w per
// axis: at most (ceil(max_dim / w) + 1)^3, and, as ceil(d / w) + 1 <= d / w + 2, at most
// max_voxels / w^3 + 6 max_dim^2 / w^2 + 12 max_dim / w + 8 (the bound that holds when max_dim
// allows long thin boxes: 4097 x 4097 x 60 is as many voxels as 1025^3). OpenVDB allocates every
// node a file names before the active box can be checked, so a damaged or crafted file otherwise
// costs ~30x its size: an internal node of 4096^3 voxels is ~260 KB from ~8 KB of file.
class NodeBudget {
 public:
  explicit NodeBudget(const VolumeLimits& limits) : limits_(limits) {
    const double dim = limits.max_dim, voxels = double(limits.max_voxels);
    for (int l = 0; l < 3; ++l) {
      const double width = double(int64_t{1} << kWidthLog2[l]);
      const double across = std::ceil(dim / width) + 1;
      const double nodes = std::min(across * across * across, voxels / (width * width * width) +
                                                                  6 * dim * dim / (width * width) +
                                                                  12 * dim / width + 8);
      max_bytes_ += int64_t(2 * nodes) * kBytes[l];
    }
  }
  void StartTree() { bytes_ = 0; }
  // One more node at `level`: 0 for 4096^3 voxels, 1 for 128^3, 2 for a leaf. False once the
  // tree is over budget.
  bool Add(int level) { return (bytes_ += kBytes[level]) <= max_bytes_; }
  std::string Exceeded(const std::string& where) const {
    return where + "'s tree would take more than " + std::to_string(max_bytes_ >> 20) +
           " MB, twice what a volume within the limits of " + std::to_string(limits_.max_dim) +
           " samples per axis and " + std::to_string(limits_.max_voxels) + " in all can need";
  }

 private:
  using Internal5 = openvdb::FloatTree::RootNodeType::ChildNodeType;
  using Internal4 = Internal5::ChildNodeType;
  using Leaf = Internal4::ChildNodeType;
  static constexpr int kWidthLog2[3] = {12, 7, 3};
  static constexpr int64_t kBytes[3] = {sizeof(Internal5), sizeof(Internal4),
                                        sizeof(Leaf) + Leaf::SIZE * sizeof(float)};
  VolumeLimits limits_;
  int64_t max_bytes_ = 0;
  int64_t bytes_ = 0;
};

// Reads a file inside a window [pos, end), never past it, through a buffer that skips keep:
// the tree walk reads a few bytes per leaf and skips its values, and a stdio seek per leaf
// dropped stdio's buffer every time (a second on a 430 MB file). Not mapped: a file truncated
// meanwhile (a catalogue file being replaced) must be a short read, not SIGBUS.
class WindowReader {
 public:
  WindowReader(int fd, int64_t size) : fd_(fd), size_(size), end_(size), buffer_(1 << 20) {}

  int64_t pos() const { return pos_; }
  int64_t left() const { return end_ - pos_; }
  int64_t size() const { return size_; }
  int64_t end() const { return end_; }
  void SetEnd(int64_t end) { end_ = end; }
  bool Seek(int64_t at) {
    if (at < 0 || at > end_) return false;
    pos_ = at;
    return true;
  }
  bool Skip(int64_t n) { return n >= 0 && n <= left() && Seek(pos_ + n); }
  bool Read(void* out, int64_t n) {
    if (n < 0 || n > left()) return false;
    auto* to = static_cast<unsigned char*>(out);
    while (n > 0) {
      if (pos_ < buffer_at_ || pos_ >= buffer_at_ + buffered_) {
        const ssize_t got = pread(fd_, buffer_.data(), buffer_.size(), pos_);
        if (got <= 0) return false;
        buffer_at_ = pos_, buffered_ = got;
      }
      const int64_t from = pos_ - buffer_at_, take = std::min(n, buffered_ - from);
      std::memcpy(to, buffer_.data() + from, size_t(take));
      to += take, pos_ += take, n -= take;
    }
    return true;
  }
  template <typename T>
  bool Get(T* v) {
    return Read(v, sizeof(T));
  }

 private:
  int fd_;
  int64_t size_;
  int64_t end_;
  int64_t pos_ = 0;
  std::vector<unsigned char> buffer_;
  int64_t buffer_at_ = 0, buffered_ = 0;
};

class VdbStructure {
 public:
  VdbStructure(WindowReader* in, const VolumeLimits& limits) : in_(*in), budget_(limits) {}

  // The whole file; false with defect() set at the first fault.
  bool Check() {
    if (!Header() || !MetaMap("file metadata")) return false;
    int32_t grids = 0;
    const int64_t count_at = in_.pos();
    if (!Get(&grids, "grid count")) return false;
    // A descriptor is at least three string lengths and three offsets.
    if (grids < 0 || int64_t{grids} * 36 > in_.left())
      return Fail(count_at, "grid count " + std::to_string(grids) + " does not fit the file");
    if (!has_offsets_ && grids > 1)
      return Unsupported(count_at,
                         "several grids written without grid offsets (a stream): "
                         "save the file with openvdb::io::File");
    for (int32_t g = 0; g < grids; ++g)
      if (!Grid(g)) return false;
    return Reachable(count_at);
  }

  const Defect& defect() const { return defect_; }

 private:
  // What a grid descriptor and its metadata say, for the rules across grids.
  struct GridEntry {
    std::string unique_name, name, type, parent;  // name: the unique name without its suffix
    bool is_float = false;
    bool has_name_meta = false;
    std::string name_meta;  // the grid's "name" metadata
  };

  // Only float trees are walked, so no other tree may ever be read: OpenVDB reads every grid of
  // a file without offsets, an instance's parent whatever its type, and the first grid of a
  // name (the loader asks for the chosen grid by the name in its metadata).
  // One pass with hash lookups: comparing every grid with every other took minutes for a
  // file of 80,000 empty grids (41 MB).
  bool Reachable(int64_t at) {
    // Grids an instance may name as its parent (not instances themselves), by unique name and
    // type; and the first grid of each name, with its index.
    std::unordered_set<std::string> parents;
    for (const GridEntry& p : grids_)
      if (p.parent.empty()) parents.insert(p.unique_name + '\0' + p.type);
    std::unordered_map<std::string, size_t> first_of_name;
    for (size_t i = 0; i < grids_.size(); ++i) {
      const GridEntry& g = grids_[i];
      const std::string where = "grid " + std::to_string(i);
      if (!has_offsets_ && !g.is_float)
        return Unsupported(at, "holds no float grid (" + g.type + ", written as a stream)");
      if (g.has_name_meta && g.name_meta != g.name)
        return Fail(at, where + " is named '" + g.name + "' in its descriptor and '" + g.name_meta +
                            "' in its metadata");
      if (!g.parent.empty() && !parents.count(g.parent + '\0' + g.type))
        return Fail(at, where + " is an instance of no grid of its type");
      // Every earlier grid of this name is as float as the first (else refused already).
      const auto [first, added] = first_of_name.emplace(g.name, i);
      const size_t j = first->second;
      if (!added && grids_[j].is_float != g.is_float)
        return Unsupported(at, "grids " + std::to_string(j) + " and " + std::to_string(i) +
                                   " are both named '" + g.name +
                                   "', one float and one not (OpenVDB finds the first by "
                                   "name): rename one");
    }
    return true;
  }

  bool Fail(int64_t at, std::string what) {
    defect_ = {at, std::move(what), false};
    return false;
  }
  bool Unsupported(int64_t at, std::string what) {
    defect_ = {at, std::move(what), true};
    return false;
  }
  // One more node at `level` (NodeBudget::Add) in the current tree.
  bool CountNode(int level, int64_t at, const std::string& where) {
    if (budget_.Add(level)) return true;
    defect_ = {at, budget_.Exceeded(where), false, true};
    return false;
  }
  template <typename T>
  bool Get(T* v, const char* what) {
    const int64_t at = in_.pos();
    return in_.Get(v) || Fail(at, std::string(what) + " runs past its end");
  }

  // OpenVDB's string: a uint32 length, then the bytes.
  bool String(std::string* out, const char* what) {
    const int64_t at = in_.pos();
    uint32_t length = 0;
    if (!Get(&length, what)) return false;
    if (int64_t{length} > in_.left())
      return Fail(at, std::string(what) + " claims " + std::to_string(length) + " bytes");
    out->resize(length);
    return length == 0 || in_.Read(out->data(), length) || Fail(at, what);
  }

  bool Header() {
    unsigned char magic[8];
    const int64_t expected = openvdb::OPENVDB_MAGIC;
    if (!in_.Read(magic, 8) || std::memcmp(magic, &expected, 8) != 0)
      return Unsupported(0, "not an OpenVDB file (wrong magic number)");
    uint32_t version = 0, library[2];
    if (!Get(&version, "file version")) return false;
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION ||
        version > openvdb::OPENVDB_FILE_VERSION)
      return Unsupported(
          8, "file format version " + std::to_string(version) + " (this build reads " +
                 std::to_string(openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) + "-" +
                 std::to_string(openvdb::OPENVDB_FILE_VERSION) +
                 ": files written by OpenVDB 3 or later)");
    if (!Get(&library[0], "library version") || !Get(&library[1], "library version")) return false;
    uint8_t offsets = 0;
    if (!Get(&offsets, "grid offset flag")) return false;
    if (offsets > 1) return Fail(in_.pos() - 1, "grid offset flag is " + std::to_string(offsets));
    has_offsets_ = offsets == 1;
    // The UUID as text, 8-4-4-4-12 hex digits: OpenVDB reads it with operator>>, and a
    // malformed one fails the stream silently, after which every count it reads is garbage.
    char uuid[36];
    const int64_t uuid_at = in_.pos();
    if (!in_.Read(uuid, 36)) return Fail(uuid_at, "file UUID runs past the end");
    for (int i = 0; i < 36; ++i) {
      const bool dash = i == 8 || i == 13 || i == 18 || i == 23;
      if (dash ? uuid[i] != '-' : !std::isxdigit(static_cast<unsigned char>(uuid[i])))
        return Fail(uuid_at + i, "file UUID is malformed");
    }
    return true;
  }

  // MetaMap::readMeta: a count, then (name, type name, byte size, value) per entry.
  bool MetaMap(const char* what) {
    const int64_t at = in_.pos();
    uint32_t count = 0;
    if (!Get(&count, what)) return false;
    if (int64_t{count} * 12 > in_.left())
      return Fail(at, std::string(what) + " claims " + std::to_string(count) + " entries");
    for (uint32_t i = 0; i < count; ++i) {
      std::string name, type;
      if (!String(&name, "metadata name") || !String(&type, "metadata type")) return false;
      if (!MetadataValue(name, type)) return false;
    }
    return true;
  }

  bool MetadataValue(const std::string& name, const std::string& type) {
    const int64_t at = in_.pos();
    uint32_t bytes = 0;
    if (!Get(&bytes, "metadata size")) return false;
    const std::string where = "metadata '" + name + "' (" + type + ")";
    if (int64_t{bytes} > in_.left())
      return Fail(at, where + " claims " + std::to_string(bytes) + " bytes");
    const int64_t value_end = in_.pos() + bytes;
    if (type == "__delayedload") return DelayedLoad(bytes, value_end, where);
    if (name_meta_ != nullptr && name == "name" && type == "string") {
      name_meta_->has_name_meta = true;
      name_meta_->name_meta.resize(bytes);
      return bytes == 0 || in_.Read(name_meta_->name_meta.data(), bytes) || Fail(at, where);
    }
    if (type != "string" && openvdb::Metadata::isRegisteredType(type)) {
      // A typed value is read at its type's size whatever the size field says: a mismatch
      // would shift every read after it.
      const uint32_t size = openvdb::Metadata::createMetadata(type)->size();
      if (bytes != size)
        return Fail(at, where + " has " + std::to_string(bytes) + " bytes, its type " +
                            std::to_string(size));
    }
    return in_.Skip(bytes) || Fail(at, where);
  }

  // io::DelayedLoadMetadata: per-leaf masks and compressed sizes, each either raw (a zero byte
  // count) or a Blosc buffer whose header states the size OpenVDB reserves for it.
  bool DelayedLoad(uint32_t bytes, int64_t value_end, const std::string& where) {
    if (bytes == 0) return true;
    const int64_t saved_end = in_.end();
    in_.SetEnd(value_end);  // OpenVDB reads what it needs, so a short value is a fault
    const bool ok = DelayedLoadParts(where);
    in_.SetEnd(saved_end);
    return ok && (in_.Seek(value_end) || Fail(value_end, where));
  }
  bool DelayedLoadParts(const std::string& where) {
    const int64_t at = in_.pos();
    uint32_t count = 0;
    if (!Get(&count, "delayed-load count")) return false;
    // One entry per leaf node, each of which takes at least a 64-byte mask in the file.
    if (int64_t{count} * 64 > in_.size() + (int64_t{1} << 20))
      return Fail(at, where + " counts " + std::to_string(count) + " leaves");
    for (int part = 0; part < 2; ++part) {
      const int64_t element = part == 0 ? 1 : 8;  // mask bytes, then compressed sizes
      const int64_t size_at = in_.pos();
      uint32_t compressed = 0;
      if (!Get(&compressed, "delayed-load part size")) return false;
      if (part == 1 && compressed == UINT32_MAX) return true;  // no compressed sizes
      if (compressed == 0) {
        if (!in_.Skip(int64_t{count} * element)) return Fail(size_at, where + " is short");
        continue;
      }
      unsigned char blosc[16];
      if (compressed < sizeof(blosc) || !in_.Read(blosc, sizeof(blosc)))
        return Fail(size_at, where + " holds a damaged compressed part");
      uint32_t uncompressed = 0;
      std::memcpy(&uncompressed, blosc + 4, 4);
      // OpenVDB pads an input of 48-127 bytes to 128 before compressing it.
      if (int64_t{uncompressed} > std::max<int64_t>(int64_t{count} * element, 128) + 64)
        return Fail(size_at + 4,
                    where + " would unpack to " + std::to_string(uncompressed) + " bytes");
      if (!BloscSizeMatches(blosc, compressed)) return Fail(size_at, where + " is damaged");
      if (!in_.Skip(int64_t{compressed} - int64_t{sizeof(blosc)}))
        return Fail(size_at, where + " is short");
    }
    return true;
  }

  // Blosc trusts its header's compressed size (bytes 12-15) and reads that far: it must be the
  // size of the buffer OpenVDB hands it.
  static bool BloscSizeMatches(const unsigned char* header, int64_t buffer_bytes) {
    uint32_t compressed = 0;
    std::memcpy(&compressed, header + 12, 4);
    return int64_t{compressed} == buffer_bytes;
  }

  // GridDescriptor::read, then the grid at its offsets (or inline, in a stream-written file).
  bool Grid(int32_t index) {
    const std::string where = "grid " + std::to_string(index);
    std::string unique_name, type, parent;
    if (!String(&unique_name, "grid name") || !String(&type, "grid type") ||
        !String(&parent, "instance parent name"))
      return false;
    const int64_t offsets_at = in_.pos();
    int64_t grid_pos = 0, block_pos = 0, end_pos = 0;
    if (!Get(&grid_pos, "grid offsets") || !Get(&block_pos, "grid offsets") ||
        !Get(&end_pos, "grid offsets"))
      return false;
    const bool instance = !parent.empty();
    GridEntry entry;
    entry.unique_name = unique_name;
    entry.name = unique_name.substr(0, unique_name.find('\x1e'));  // GridDescriptor::stripSuffix
    entry.parent = parent;
    entry.type = std::string(absl::StripSuffix(type, "_HalfFloat"));  // as GridDescriptor::read
    entry.is_float = entry.type == "Tree_float_5_4_3";
    grids_.push_back(entry);
    if (has_offsets_) {
      // OpenVDB writes a grid right after its descriptor, and io::Stream (the loader's reader
      // for one-grid files) reads it from there, whatever the offset says.
      if (grid_pos != in_.pos())
        return Fail(offsets_at, where + " does not start right after its descriptor");
      // An instance has no tree, and its descriptor no block offset.
      const int64_t topology_end = instance ? end_pos : block_pos;
      if (grid_pos < in_.pos() || grid_pos > topology_end || topology_end > end_pos ||
          end_pos > in_.size())
        return Fail(offsets_at, where + " offsets " + std::to_string(grid_pos) + ", " +
                                    std::to_string(block_pos) + ", " + std::to_string(end_pos) +
                                    " lie outside the file");
      if (!in_.Seek(grid_pos)) return Fail(grid_pos, where);
      in_.SetEnd(topology_end);  // the metadata, transform and topology come before it
      grid_end_ = end_pos;
    } else {
      grid_end_ = in_.size();
    }
    const bool ok = GridBody(type, !instance, where);
    in_.SetEnd(in_.size());
    return ok && (!has_offsets_ || in_.Seek(end_pos) || Fail(end_pos, where));
  }

  // Archive::readGrid up to the voxel data: compression flags, metadata, transform, and for a
  // float tree its root's tile and child counts.
  bool GridBody(const std::string& type, bool has_tree, const std::string& where) {
    const int64_t at = in_.pos();
    uint32_t compression = 0;
    if (!Get(&compression, "compression flags")) return false;
    if (compression > (openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK |
                       openvdb::io::COMPRESS_BLOSC))
      return Fail(at, where + " compression flags " + std::to_string(compression));
    name_meta_ = &grids_.back();
    const bool described = MetaMap("grid metadata");
    name_meta_ = nullptr;
    if (!described || !Transform(where)) return false;
    // Other trees are never read (Reachable): the loader reads float grids only.
    if (!has_tree || !grids_.back().is_float) return true;
    const int64_t tree_at = in_.pos();
    int32_t buffers = 0;
    if (!Get(&buffers, "buffer count")) return false;
    if (buffers != 1) return Fail(tree_at, where + " has " + std::to_string(buffers) + " buffers");
    float background = 0;
    uint32_t tiles = 0, children = 0;
    const int64_t counts_at = in_.pos() + 4;
    if (!Get(&background, "background") || !Get(&tiles, "root counts") ||
        !Get(&children, "root counts"))
      return false;
    // A tile is its origin, value and active flag; a child at least its origin and the two
    // 32^3-bit masks of a 5-level internal node.
    constexpr int64_t kTileBytes = 12 + 4 + 1, kChildBytes = 12 + 2 * 4096;
    if (int64_t{tiles} * kTileBytes + int64_t{children} * kChildBytes > in_.left())
      return Fail(counts_at, where + " root claims " + std::to_string(tiles) + " tiles and " +
                                 std::to_string(children) + " children");
    compression_ = compression;
    half_ = type != grids_.back().type;  // the descriptor's type carried "_HalfFloat"
    return Tree(tiles, children, where);
  }

  // The root's tiles and children, every node below them, and then every leaf's values.
  // OpenVDB reads the values of leaves in the order of the root's std::map<Coord> (a later
  // entry at the same origin replacing an earlier one), so that is mirrored here.
  bool Tree(uint32_t tiles, uint32_t children, const std::string& where) {
    budget_.StartTree();
    std::map<std::array<int32_t, 3>, int> table;  // origin -> child (-1: a tile)
    // OpenVDB keeps a root entry under the origin it reads; lookups go to the multiple of 4096
    // below a voxel, so an entry elsewhere (one flipped bit) is never found, and every sample
    // under it would read as the background.
    auto misplaced = [&](const std::array<int32_t, 3>& origin, int64_t at, const char* what) {
      if (((origin[0] | origin[1] | origin[2]) & 4095) == 0) return false;
      Fail(at, where + " " + what + " origin (" + std::to_string(origin[0]) + ", " +
                   std::to_string(origin[1]) + ", " + std::to_string(origin[2]) +
                   ") is not a multiple of 4096");
      return true;
    };
    for (uint32_t t = 0; t < tiles; ++t) {
      std::array<int32_t, 3> origin;
      const int64_t at = in_.pos();
      if (!Get(&origin, "root tile") || !in_.Skip(5)) return Fail(in_.pos(), where + " root tile");
      if (misplaced(origin, at, "root tile")) return false;
      table[origin] = -1;
    }
    std::vector<std::vector<Mask>> leaves(children);  // per root child, its leaves' masks
    for (uint32_t c = 0; c < children; ++c) {
      std::array<int32_t, 3> origin;
      const int64_t at = in_.pos();
      if (!Get(&origin, "root child origin")) return false;
      if (misplaced(origin, at, "root child")) return false;
      if (!CountNode(0, in_.pos(), where) || !Internal(5, &leaves[c], where)) return false;
      table[origin] = int(c);
    }
    if (has_offsets_ && in_.pos() != in_.end())
      return Fail(in_.pos(), where + " topology ends " + std::to_string(in_.end() - in_.pos()) +
                                 " bytes before its values");
    in_.SetEnd(grid_end_);
    for (const auto& [origin, child] : table) {
      if (child < 0) continue;
      for (const Mask& topology : leaves[size_t(child)]) {
        const int64_t at = in_.pos();
        Mask mask;
        if (!in_.Read(mask.data(), int64_t(mask.size())))
          return Fail(at, where + " leaf values run past the end");
        if (mask != topology) return Fail(at, where + " leaf mask differs from its topology");
        if (!Values(512, Ones(mask.data(), mask.size()), mask.size(), where)) return false;
      }
    }
    return true;
  }

  using Mask = std::array<unsigned char, 64>;  // a leaf's 8^3 value mask

  // Set bits in n bytes (a multiple of 8), a word at a time: the baseline x86-64 target has no
  // popcount instruction, and the library call per byte was most of the walk's time.
  static uint32_t Ones(const unsigned char* bytes, size_t n) {
    uint64_t ones = 0;
    for (size_t i = 0; i < n; i += 8) {
      uint64_t w;
      std::memcpy(&w, bytes + i, 8);
      w -= (w >> 1) & 0x5555555555555555ull;
      w = (w & 0x3333333333333333ull) + ((w >> 2) & 0x3333333333333333ull);
      w = (w + (w >> 4)) & 0x0f0f0f0f0f0f0f0full;
      ones += (w * 0x0101010101010101ull) >> 56;
    }
    return uint32_t(ones);
  }

  // InternalNode::readTopology with 2^(3 log2) entries: child and value masks, the node's values,
  // then its children (internal nodes of log2 4 below log2 5, leaves' masks below that).
  bool Internal(int log2, std::vector<Mask>* leaves, const std::string& where) {
    const size_t entries = size_t{1} << (3 * log2), mask_bytes = entries / 8;
    std::vector<unsigned char> masks(2 * mask_bytes);
    const int64_t at = in_.pos();
    if (!in_.Read(masks.data(), int64_t(masks.size())))
      return Fail(at, where + " node masks run past the end");
    if (!Values(uint32_t(entries), Ones(masks.data() + mask_bytes, mask_bytes), mask_bytes, where))
      return false;
    for (size_t i = 0; i < entries; ++i) {
      if (masks[i / 8] == 0) {  // most of a sparse node's mask
        i += 7;
        continue;
      }
      if (!((masks[i / 8] >> (i % 8)) & 1)) continue;
      if (log2 == 5) {
        if (!CountNode(1, in_.pos(), where) || !Internal(4, leaves, where)) return false;
        continue;
      }
      Mask mask;
      const int64_t leaf_at = in_.pos();
      if (!CountNode(2, leaf_at, where)) return false;
      if (!in_.Read(mask.data(), int64_t(mask.size())))
        return Fail(leaf_at, where + " leaf mask runs past the end");
      leaves->push_back(mask);
    }
    return true;
  }

  // io::readCompressedValues for `count` values of a node whose value mask has `on` bits: a
  // flag byte, inactive values and a selection mask as the flag says, then the values (only the
  // active ones when the grid compresses by mask), raw, or as a Zip or Blosc chunk whose size
  // field OpenVDB trusts for raw data (it reads that many bytes into a buffer of the expected
  // size, then compares).
  bool Values(uint32_t count, uint32_t on, size_t mask_bytes, const std::string& where) {
    const int64_t at = in_.pos();
    int8_t flag = 0;
    if (!Get(&flag, "value flags")) return false;
    const bool one_inactive = flag == 2 || flag == 4 || flag == 5,
               selection = flag >= 3 && flag <= 5;
    if (!in_.Skip((one_inactive ? 4 : 0) + (flag == 5 ? 4 : 0) +
                  (selection ? int64_t(mask_bytes) : 0)))
      return Fail(at, where + " node values run past the end");
    const bool by_mask = (compression_ & openvdb::io::COMPRESS_ACTIVE_MASK) && flag != 6;
    const uint32_t stored = by_mask ? on : count;
    if (half_ && stored == 0) return true;  // OpenVDB reads nothing then
    const int64_t bytes = int64_t{stored} * (half_ ? 2 : 4);
    if (!(compression_ & (openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_BLOSC)))
      return in_.Skip(bytes) || Fail(at, where + " node values run past the end");
    const int64_t size_at = in_.pos();
    int64_t chunk = 0;
    if (!Get(&chunk, "value chunk size")) return false;
    if (chunk <= 0) {  // raw: minus its size
      if (chunk != -bytes)
        return Fail(size_at, where + " holds a raw chunk sized " + std::to_string(chunk) +
                                 " where " + std::to_string(bytes) + " bytes belong");
      return in_.Skip(bytes) || Fail(size_at, where + " node values run past the end");
    }
    if (chunk > in_.left())
      return Fail(size_at,
                  where + " chunk of " + std::to_string(chunk) + " bytes runs past the end");
    if (compression_ & openvdb::io::COMPRESS_BLOSC) {
      unsigned char header[16];
      uint32_t unpacked = 0;
      if (chunk < 16 || !in_.Read(header, 16))
        return Fail(size_at, where + " holds a damaged Blosc chunk");
      std::memcpy(&unpacked, header + 4, 4);
      if (!BloscSizeMatches(header, chunk))
        return Fail(size_at, where + " holds a Blosc chunk of another size than its field");
      if (int64_t{unpacked} != bytes)
        return Fail(size_at, where + " Blosc chunk unpacks to " + std::to_string(unpacked) +
                                 " bytes where " + std::to_string(bytes) + " belong");
      chunk -= 16;
    }
    return in_.Skip(chunk) || Fail(size_at, where + " chunk runs past the end");
  }

  // Transform::read: the map's type name, then its fields. A frustum map holds a box, its taper
  // and depth, then a second map (linear, or OpenVDB would refuse it: at most one level here).
  // The loader refuses non-linear transforms on the grid it reads; other grids may have them.
  bool Transform(const std::string& where, int depth = 0) {
    const int64_t at = in_.pos();
    std::string map;
    if (!String(&map, "transform type")) return false;
    int64_t bytes = -1;
    if (map == "AffineMap" || map == "UnitaryMap") bytes = 16 * 8;      // a 4x4 double matrix
    if (map == "ScaleMap" || map == "UniformScaleMap") bytes = 5 * 24;  // five double vectors
    if (map == "ScaleTranslateMap" || map == "UniformScaleTranslateMap") bytes = 6 * 24;
    if (map == "TranslationMap") bytes = 24;
    if (map == "NonlinearFrustumMap" && depth == 0) {
      return (in_.Skip(48 + 16) || Fail(at, where + " transform runs past its end")) &&
             Transform(where, depth + 1);
    }
    if (bytes < 0) return Fail(at, where + " has an unknown transform '" + map + "'");
    return in_.Skip(bytes) || Fail(at, where + " transform runs past its end");
  }

  WindowReader& in_;
  bool has_offsets_ = true;
  std::vector<GridEntry> grids_;
  GridEntry* name_meta_ = nullptr;  // while reading a grid's metadata: where its name goes
  int64_t grid_end_ = 0;            // the current grid's
  uint32_t compression_ = 0;        // the current grid's compression flags
  bool half_ = false;               // the current grid stores its values as 16-bit floats
  NodeBudget budget_;
  Defect defect_;
};

}  // namespace

absl::Status CheckVdbStructure(int fd, const std::string& path, const VolumeLimits& limits) {
  struct stat st;
  if (fstat(fd, &st) != 0) return absl::DataLossError(path + ": cannot read its size");
  WindowReader in(fd, int64_t(st.st_size));
  VdbStructure structure(&in, limits);
  if (structure.Check()) return absl::OkStatus();
  const Defect& d = structure.defect();
  if (d.unsupported) return absl::InvalidArgumentError(path + ": " + d.what);
  if (d.too_big) return absl::ResourceExhaustedError(path + ": " + d.what);
  return absl::DataLossError(path + ": corrupt OpenVDB file (byte " + std::to_string(d.at) + ": " +
                             d.what + ")");
}

absl::Status CheckVdbStructure(const std::string& path, const VolumeLimits& limits) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return absl::NotFoundError(path + ": cannot open");
  const absl::Status status = CheckVdbStructure(fd, path, limits);
  close(fd);
  return status;
}

}  // namespace isostream
