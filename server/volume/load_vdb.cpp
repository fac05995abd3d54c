// OpenVDB files: one float grid becomes a Volume over its active bounding box.
#include <fcntl.h>
#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/math/Maps.h>
#include <sys/stat.h>
#include <tbb/combinable.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <mutex>
#include <string>

#include "server/volume/grid_blocks.h"
#include "server/volume/loaders.h"
#include "server/volume/orientation.h"
#include "server/volume/sample_reader.h"
#include "server/volume/vdb_structure.h"

namespace isostream {
namespace {

void InitializeOpenVdbOnce() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// In 64 bits: CoordBBox::dim() overflows int32 for a box spanning more than half the index
// range (a damaged file can place voxels anywhere).
std::array<int64_t, 3> BoxDims(const openvdb::CoordBBox& box) {
  const openvdb::Coord lo = box.min(), hi = box.max();
  return {int64_t{hi.x()} - lo.x() + 1, int64_t{hi.y()} - lo.y() + 1, int64_t{hi.z()} - lo.z() + 1};
}

struct BoxScan {
  float min_value = std::numeric_limits<float>::max();
  float max_value = std::numeric_limits<float>::lowest();
  int64_t first_bad = -1;  // x-fastest index within the box
};

// Range and first non-finite sample over every sample of BOX, active or not: the volume's
// samples are all values in the box, including tile and background values.
BoxScan ScanBox(const openvdb::FloatGrid& grid, const openvdb::CoordBBox& box) {
  const openvdb::Coord lo = box.min(), dim = box.dim();
  tbb::combinable<BoxScan> partial;
  ForEachBlock(grid, box, [&](const openvdb::CoordBBox& block, const float* leaf, float value) {
    BoxScan& s = partial.local();
    const auto note_bad = [&](int x, int y, int z) {
      const int64_t index = (int64_t{z - lo.z()} * dim.y() + (y - lo.y())) * dim.x() + (x - lo.x());
      if (s.first_bad < 0 || index < s.first_bad) s.first_bad = index;
    };
    if (leaf == nullptr) {
      if (std::isfinite(value)) {
        s.min_value = std::min(s.min_value, value);
        s.max_value = std::max(s.max_value, value);
      } else {
        note_bad(block.min().x(), block.min().y(), block.min().z());
      }
      return;
    }
    for (int z = block.min().z(); z <= block.max().z(); ++z) {
      for (int y = block.min().y(); y <= block.max().y(); ++y) {
        for (int x = block.min().x(); x <= block.max().x(); ++x) {
          const float v = leaf[LeafOffset(openvdb::Coord(x, y, z))];
          if (!std::isfinite(v)) {
            note_bad(x, y, z);
            continue;
          }
          s.min_value = std::min(s.min_value, v);
          s.max_value = std::max(s.max_value, v);
        }
      }
    }
  });
  BoxScan total;
  partial.combine_each([&](const BoxScan& s) {
    total.min_value = std::min(total.min_value, s.min_value);
    total.max_value = std::max(total.max_value, s.max_value);
    if (s.first_bad >= 0 && (total.first_bad < 0 || s.first_bad < total.first_bad)) {
      total.first_bad = s.first_bad;
    }
  });
  return total;
}

}  // namespace

absl::StatusOr<VolumePtr> LoadVdbFile(const std::string& spec, const std::string& path,
                                      const std::string& grid_name, const VolumeLimits& limits) {
  ISOSTREAM_RETURN_IF_ERROR(CheckInputFile(path));
  struct Closer {
    int fd;
    ~Closer() {
      if (fd >= 0) close(fd);
    }
  } opened{open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK)};  // a FIFO must not block
  if (opened.fd < 0) return absl::ErrnoToStatus(errno, path + ": cannot open");
  struct stat st;  // what was opened, which may not be what CheckInputFile saw
  if (fstat(opened.fd, &st) != 0 || !S_ISREG(st.st_mode))
    return absl::InvalidArgumentError(path + ": not a regular file");
  return LoadVdbOpenFile(opened.fd, spec, path, grid_name, limits);
}

absl::StatusOr<VolumePtr> LoadVdbOpenFile(int fd, const std::string& spec, const std::string& path,
                                          const std::string& grid_name,
                                          const VolumeLimits& limits) {
  InitializeOpenVdbOnce();
  // A foreign file is InvalidArgument, a damaged one DataLoss (OpenVDB reports both alike).
  ISOSTREAM_RETURN_IF_ERROR(CheckVdbStructure(fd, path, limits));

  // OpenVDB opens files by name. Through the descriptor's /proc entry it reads the very file
  // just checked, even if PATH has since been replaced (a catalogue updated by renaming a new
  // file over the old one); by PATH it would read the new file unchecked.
  std::string checked_file = "/proc/self/fd/" + std::to_string(fd);
  if (::access(checked_file.c_str(), R_OK) != 0) checked_file = path;  // no /proc mounted
  openvdb::io::File file(checked_file);
  try {
    // Delayed loading would defer reading (and its errors) to first access, past this edge.
    file.open(/*delayLoad=*/false);
  } catch (const openvdb::LookupError& e) {
    // A sound file holding a grid type this build does not know (a newer library's, a custom
    // tree): OpenVDB opens the file's grids all at once, so none of them can be read here.
    return absl::InvalidArgumentError(path + ": holds a grid type this OpenVDB (" +
                                      openvdb::getLibraryVersionString() +
                                      ") cannot read, so none of its grids can be: " + e.what());
  } catch (const std::exception& e) {
    return absl::DataLossError(path + ": corrupt or truncated OpenVDB file: " + e.what());
  }

  // Choose the grid from metadata alone, and check its recorded size before reading voxels.
  openvdb::GridPtrVecPtr metadata;
  try {
    metadata = file.readAllGridMetadata();
  } catch (const std::exception& e) {
    return absl::DataLossError(path + ": corrupt OpenVDB grid metadata: " + e.what());
  }
  openvdb::GridBase::Ptr chosen;
  for (const openvdb::GridBase::Ptr& g : *metadata) {
    if (grid_name.empty() ? g->isType<openvdb::FloatGrid>() : g->getName() == grid_name) {
      chosen = g;
      break;
    }
  }
  if (metadata->empty())
    return absl::DataLossError(path + ": holds no grids (an empty or truncated file)");
  if (chosen == nullptr) {
    // What there is to choose from, name and type (the first 8).
    std::string grids;
    for (size_t i = 0; i < metadata->size() && i < 8; ++i) {
      const openvdb::GridBase& g = *(*metadata)[i];
      grids += (i > 0 ? ", '" : "'") + g.getName() + "' (" + g.type() + ")";
    }
    if (metadata->size() > 8) grids += ", ...";
    if (!grid_name.empty())
      return absl::NotFoundError(path + ": no grid named '" + grid_name + "'; it holds " + grids);
    return absl::InvalidArgumentError(path + ": no float grid; it holds " + grids);
  }
  if (!chosen->isType<openvdb::FloatGrid>()) {
    return absl::InvalidArgumentError(path + ": grid '" + grid_name + "' has unsupported type " +
                                      chosen->type() + " (only float grids load)");
  }
  const std::string where = path + " grid '" + chosen->getName() + "'";
  try {
    const openvdb::Vec3i file_min =
        chosen->metaValue<openvdb::Vec3i>(openvdb::GridBase::META_FILE_BBOX_MIN);
    const openvdb::Vec3i file_max =
        chosen->metaValue<openvdb::Vec3i>(openvdb::GridBase::META_FILE_BBOX_MAX);
    const std::array<int64_t, 3> recorded = {int64_t{file_max.x()} - file_min.x() + 1,
                                             int64_t{file_max.y()} - file_min.y() + 1,
                                             int64_t{file_max.z()} - file_min.z() + 1};
    // An empty grid records an inverted box; the check after reading reports it properly.
    if (recorded[0] > 0 && recorded[1] > 0 && recorded[2] > 0) {
      ISOSTREAM_RETURN_IF_ERROR(CheckDims(recorded, limits, where));
    }
  } catch (const openvdb::Exception&) {
    // Older writers do not record the bounding box; the check after reading still applies.
  }

  openvdb::FloatGrid::Ptr grid;
  try {
    if (metadata->size() == 1) {
      // OpenVDB does not check that its reads were complete: a file missing its last few
      // bytes loads with garbage in its last voxels. Through our own stream the short read
      // shows (a single grid: the stream reads every grid, which is then just this one).
      file.close();
      std::ifstream in(checked_file, std::ios::binary);
      openvdb::io::Stream stream(in, /*delayLoad=*/false);
      const openvdb::GridPtrVecPtr grids = stream.getGrids();
      if (!in) return absl::DataLossError(where + ": truncated grid data");
      if (grids && grids->size() == 1)
        grid = openvdb::gridPtrCast<openvdb::FloatGrid>(grids->front());
    } else {
      grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(chosen->getName()));
      file.close();
    }
  } catch (const std::exception& e) {
    return absl::DataLossError(where + ": corrupt or truncated grid data: " + e.what());
  }
  if (grid == nullptr) return absl::DataLossError(where + ": grid did not read as a float grid");

  openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
  if (box.empty()) return absl::InvalidArgumentError(where + ": grid has no active voxels");
  // A level set or fog volume goes on past its active voxels (inactive ones, the background):
  // its surfaces may lie between the last active voxel and what is beyond, and were cut open
  // where the active box ended. One voxel of what lies beyond closes them. A grid of another
  // class is its active box, as dense data (a scan, a simulation's domain) are: a margin of
  // background would add a surface on the box's faces, and move a 1024^3 grid past the 1025^3
  // cube.
  // The limits are the data's: a grid that fits them without the margin loads without it
  // (a 4096-wide level set would be refused as 4098 wide, dims the user never made).
  ISOSTREAM_RETURN_IF_ERROR(CheckDims(BoxDims(box), limits, where));
  if (grid->getGridClass() == openvdb::GRID_LEVEL_SET ||
      grid->getGridClass() == openvdb::GRID_FOG_VOLUME) {
    openvdb::CoordBBox wider = box;
    wider.expand(1);
    if (CheckDims(BoxDims(wider), limits, where).ok()) box = wider;
  }

  // Samples sit on an axis-aligned lattice downstream: scale + translate maps load, with axes
  // reversed or swapped (turned onto the world's, orientation.h); rotated ones do not.
  const openvdb::math::Transform& transform = grid->transform();
  if (!transform.isLinear()) {
    return absl::InvalidArgumentError(where +
                                      ": non-linear (frustum) transforms are not supported");
  }
  // A scale map whose scales nearly cancel makes OpenVDB throw here: the file's error, named.
  openvdb::Mat4d m;
  try {
    m = transform.baseMap()->getAffineMap()->getMat4();
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(where + ": degenerate transform (" + e.what() + ")");
  }
  // OpenVDB's matrices act on row vectors: index axis i steps by row i.
  std::array<std::array<double, 3>, 3> steps;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) steps[c][r] = m(r, c);
  const openvdb::Vec3d first = transform.indexToWorld(box.min());
  const openvdb::Coord dim = box.dim();
  absl::StatusOr<Orientation> orientation =
      NearestAxes(steps, {first.x(), first.y(), first.z()}, {dim.x(), dim.y(), dim.z()});
  if (!orientation.ok())
    return absl::InvalidArgumentError(where + ": degenerate transform (" +
                                      std::string(orientation.status().message()) + ")");
  if (orientation->off_axis_degrees > 0) {
    char angle[32];
    std::snprintf(angle, sizeof(angle), "%.3g", orientation->off_axis_degrees);
    return absl::InvalidArgumentError(where +
                                      ": only axis-aligned transforms are supported (this one is "
                                      "rotated " +
                                      angle + " degrees off the axes)");
  }
  ISOSTREAM_RETURN_IF_ERROR(
      CheckWorldBox(orientation->dims, orientation->spacing, orientation->origin, where));

  const BoxScan scan = ScanBox(*grid, box);
  if (scan.first_bad >= 0) {
    const int64_t plane = int64_t{dim.x()} * dim.y();
    const openvdb::Coord bad(static_cast<int>(scan.first_bad % dim.x()),
                             static_cast<int>(scan.first_bad % plane / dim.x()),
                             static_cast<int>(scan.first_bad / plane));
    const float v = grid->getConstAccessor().getValue(box.min() + bad);
    return absl::InvalidArgumentError(where + ": " + (std::isnan(v) ? "NaN" : "Inf") +
                                      " sample at index (" + std::to_string(bad.x()) + ", " +
                                      std::to_string(bad.y()) + ", " + std::to_string(bad.z()) +
                                      ")");
  }

  auto volume = std::make_shared<Volume>();
  volume->name = spec;
  volume->grid = grid;
  volume->index_min = {box.min().x(), box.min().y(), box.min().z()};
  volume->dims = {dim.x(), dim.y(), dim.z()};
  // From the matrix (the column lengths), as the checks above: a scale map also stores a voxel
  // size of its own, which OpenVDB does not check against its scales.
  for (int a = 0; a < 3; ++a) volume->spacing[orientation->source[a]] = orientation->spacing[a];
  volume->origin = orientation->origin;
  volume->min_value = scan.min_value;
  volume->max_value = scan.max_value;
  if (orientation->identity()) return VolumePtr(std::move(volume));
  return Reorient(std::move(volume), *orientation);
}

}  // namespace isostream
