#include "shared/ply_io.h"

#include <absl/strings/str_cat.h>
#include <absl/strings/string_view.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <vector>

#include "shared/file_io.h"
#include "shared/mesh_validate.h"

// Binary PLY is read and written with memcpy of host values.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "ply_io assumes a little-endian host");

namespace isostream {
namespace {

// ---------------------------------------------------------------------------------------------
// Writing

char* PutRaw(char* at, const void* from, size_t size) {
  std::memcpy(at, from, size);
  return at + size;
}

void AppendText(std::string* out, float value) {
  char text[32];
  // Shortest representation that parses back to the same float: ascii files round-trip exactly.
  const auto result = std::to_chars(text, text + sizeof(text), value);
  out->append(text, result.ptr);
}

void AppendText(std::string* out, uint32_t value) {
  char text[16];
  const auto result = std::to_chars(text, text + sizeof(text), value);
  out->append(text, result.ptr);
}

std::string PlyHeader(const OrderedMesh& mesh, bool binary) {
  return absl::StrCat("ply\nformat ", binary ? "binary_little_endian" : "ascii",
                      " 1.0\n"
                      "comment isostream OrderedMesh: faces in draw order"
                      " (back to front unless extracted unordered)\n"
                      "element vertex ",
                      mesh.vertex_count(),
                      "\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      "property float nx\nproperty float ny\nproperty float nz\n"
                      "element face ",
                      mesh.triangle_count(),
                      "\n"
                      "property list uchar uint vertex_indices\n"
                      "property uchar surface\n"
                      "end_header\n");
}

// ---------------------------------------------------------------------------------------------
// Reading

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

size_t TypeBytes(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 1;
}

std::optional<PlyType> ParseTypeName(absl::string_view name) {
  if (name == "char" || name == "int8") return PlyType::kInt8;
  if (name == "uchar" || name == "uint8") return PlyType::kUint8;
  if (name == "short" || name == "int16") return PlyType::kInt16;
  if (name == "ushort" || name == "uint16") return PlyType::kUint16;
  if (name == "int" || name == "int32") return PlyType::kInt32;
  if (name == "uint" || name == "uint32") return PlyType::kUint32;
  if (name == "float" || name == "float32") return PlyType::kFloat32;
  if (name == "double" || name == "float64") return PlyType::kFloat64;
  return std::nullopt;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;  // element type for lists
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeaderInfo {
  bool binary = false;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;
};

std::vector<absl::string_view> SplitWords(absl::string_view line) {
  std::vector<absl::string_view> words;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

absl::StatusOr<PlyHeaderInfo> ParseHeader(absl::string_view bytes) {
  PlyHeaderInfo info;
  size_t pos = 0;
  int line_number = 0;
  bool have_format = false;
  auto error = [&](absl::string_view what) {
    return absl::InvalidArgumentError(absl::StrCat("PLY header line ", line_number, ": ", what));
  };
  while (true) {
    const size_t newline = bytes.find('\n', pos);
    if (newline == absl::string_view::npos) {
      return absl::InvalidArgumentError(line_number == 0 ? "not a PLY file (empty)"
                                                         : "PLY header has no end_header line");
    }
    const absl::string_view line = bytes.substr(pos, newline - pos);
    pos = newline + 1;
    ++line_number;
    const std::vector<absl::string_view> words = SplitWords(line);
    if (line_number == 1) {
      if (words.size() != 1 || words[0] != "ply") {
        return absl::InvalidArgumentError("not a PLY file (first line is not \"ply\")");
      }
      continue;
    }
    if (words.empty() || words[0] == "comment" || words[0] == "obj_info") continue;
    if (words[0] == "end_header") break;
    if (words[0] == "format") {
      if (words.size() != 3 || words[2] != "1.0") return error("expected \"format <type> 1.0\"");
      if (words[1] == "ascii") {
        info.binary = false;
      } else if (words[1] == "binary_little_endian") {
        info.binary = true;
      } else if (words[1] == "binary_big_endian") {
        return absl::UnimplementedError("big-endian PLY is not supported; convert it first");
      } else {
        return error(absl::StrCat("unknown format \"", words[1], "\""));
      }
      have_format = true;
    } else if (words[0] == "element") {
      uint64_t count = 0;
      if (words.size() != 3) return error("expected \"element <name> <count>\"");
      const auto parsed =
          std::from_chars(words[2].data(), words[2].data() + words[2].size(), count);
      if (parsed.ec != std::errc() || parsed.ptr != words[2].data() + words[2].size()) {
        return error(absl::StrCat("bad element count \"", words[2], "\""));
      }
      info.elements.push_back(PlyElement{std::string(words[1]), count, {}});
    } else if (words[0] == "property") {
      if (info.elements.empty()) return error("property before any element");
      PlyProperty property;
      if (words.size() == 5 && words[1] == "list") {
        const auto count_type = ParseTypeName(words[2]);
        const auto item_type = ParseTypeName(words[3]);
        if (!count_type || !item_type) return error("unknown type in list property");
        if (*count_type == PlyType::kFloat32 || *count_type == PlyType::kFloat64) {
          return error("list count type must be an integer type");
        }
        property = PlyProperty{std::string(words[4]), *item_type, true, *count_type};
      } else if (words.size() == 3) {
        const auto type = ParseTypeName(words[1]);
        if (!type) return error(absl::StrCat("unknown property type \"", words[1], "\""));
        property = PlyProperty{std::string(words[2]), *type, false, PlyType::kUint8};
      } else {
        return error("expected \"property <type> <name>\" or \"property list <t> <t> <name>\"");
      }
      info.elements.back().properties.push_back(std::move(property));
    } else {
      return error(absl::StrCat("unknown keyword \"", words[0], "\""));
    }
  }
  if (!have_format) return absl::InvalidArgumentError("PLY header has no format line");
  info.data_offset = pos;
  return info;
}

// Reads values of the body one at a time, binary or ascii. Every read reports failure instead
// of running past the end, so truncated files surface as errors at the element they cut.
class BodyReader {
 public:
  BodyReader(absl::string_view body, bool binary)
      : p_(body.data()), end_(body.data() + body.size()), binary_(binary) {}

  bool Read(PlyType type, double* value) {
    return binary_ ? ReadBinary(type, value) : ReadText(value);
  }

  // DataLoss unless what is left can hold `element`'s items: each takes at least the bytes of
  // its properties (a list its count; ascii a character and a separator each). Checked before
  // an element is allocated, so a header cannot ask for many times the file's size.
  absl::Status CheckFits(const PlyElement& element) const {
    size_t item_bytes = 0;
    for (const PlyProperty& p : element.properties)
      item_bytes += binary_ ? TypeBytes(p.is_list ? p.count_type : p.type) : 2;
    item_bytes = std::max<size_t>(item_bytes, 1);
    const size_t left = size_t(end_ - p_);
    if (element.count <= left / item_bytes) return absl::OkStatus();
    return absl::DataLossError(absl::StrCat("element \"", element.name, "\" declares ",
                                            element.count, " items of at least ", item_bytes,
                                            " bytes but only ", left, " bytes are left"));
  }

 private:
  template <typename T>
  bool ReadAs(double* value) {
    if (static_cast<size_t>(end_ - p_) < sizeof(T)) return false;
    T raw;
    std::memcpy(&raw, p_, sizeof(T));
    p_ += sizeof(T);
    *value = static_cast<double>(raw);
    return true;
  }

  bool ReadBinary(PlyType type, double* value) {
    switch (type) {
      case PlyType::kInt8:
        return ReadAs<int8_t>(value);
      case PlyType::kUint8:
        return ReadAs<uint8_t>(value);
      case PlyType::kInt16:
        return ReadAs<int16_t>(value);
      case PlyType::kUint16:
        return ReadAs<uint16_t>(value);
      case PlyType::kInt32:
        return ReadAs<int32_t>(value);
      case PlyType::kUint32:
        return ReadAs<uint32_t>(value);
      case PlyType::kFloat32:
        return ReadAs<float>(value);
      case PlyType::kFloat64:
        return ReadAs<double>(value);
    }
    return false;
  }

  bool ReadText(double* value) {
    while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r' || *p_ == '\n')) ++p_;
    if (p_ == end_) return false;
    // from_chars rejects a leading '+', which some writers emit.
    if (*p_ == '+') ++p_;
    const auto parsed = std::from_chars(p_, end_, *value);
    if (parsed.ec != std::errc()) return false;
    p_ = parsed.ptr;
    // Values are separated by white space: "1-0" is malformed, not 1 and -0.
    return p_ == end_ || IsSpace(*p_);
  }

 public:
  // Ascii: whether only white space is left after the last element (text after it was a
  // miscounted header or a damaged file, read as if the mesh were whole).
  bool OnlySpaceLeft() const {
    if (binary_) return true;
    for (const char* q = p_; q < end_; ++q)
      if (!IsSpace(*q)) return false;
    return true;
  }

 private:
  static bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

  const char* p_;
  const char* end_;
  bool binary_;
};

bool IsIndexLike(double value, double limit) {
  return value >= 0 && value < limit && value == std::floor(value);
}

// Where the properties this reader cares about sit in their element.
struct VertexLayout {
  int position[3] = {-1, -1, -1};
  int normal[3] = {-1, -1, -1};
};

struct FaceLayout {
  int indices = -1;
  int surface = -1;
};

absl::Status ReadVertexElement(const PlyElement& element, BodyReader* reader, OrderedMesh* mesh) {
  VertexLayout layout;
  const char* names[6] = {"x", "y", "z", "nx", "ny", "nz"};
  for (size_t i = 0; i < element.properties.size(); ++i) {
    const PlyProperty& property = element.properties[i];
    for (int k = 0; k < 6; ++k) {
      if (property.name != names[k]) continue;
      if (property.is_list) {
        return absl::InvalidArgumentError(absl::StrCat("vertex property ", names[k], " is a list"));
      }
      (k < 3 ? layout.position[k] : layout.normal[k - 3]) = static_cast<int>(i);
    }
  }
  for (int k = 0; k < 3; ++k) {
    if (layout.position[k] < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex element has no \"", names[k], "\" property"));
    }
  }
  const int normal_found =
      (layout.normal[0] >= 0) + (layout.normal[1] >= 0) + (layout.normal[2] >= 0);
  if (normal_found != 0 && normal_found != 3) {
    return absl::InvalidArgumentError("vertex element has some but not all of nx, ny, nz");
  }

  ISOSTREAM_RETURN_IF_ERROR(reader->CheckFits(element));
  const size_t count = element.count;
  mesh->positions.assign(3 * count, 0.0f);
  mesh->normals.assign(3 * count, 0.0f);
  std::vector<double> values(element.properties.size());
  for (size_t v = 0; v < count; ++v) {
    for (size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      double list_count = 0;
      bool ok;
      if (property.is_list) {
        ok = reader->Read(property.count_type, &list_count) && IsIndexLike(list_count, 1e9);
        double ignored;
        for (double k = 0; ok && k < list_count; ++k) ok = reader->Read(property.type, &ignored);
      } else {
        ok = reader->Read(property.type, &values[i]);
      }
      if (!ok) {
        return absl::DataLossError(
            absl::StrCat("vertex data ends early or is malformed at vertex ", v, " of ", count));
      }
    }
    for (int k = 0; k < 3; ++k) {
      const float position = static_cast<float>(values[layout.position[k]]);
      if (!std::isfinite(position)) {
        return absl::InvalidArgumentError(absl::StrCat("vertex ", v, " has a non-finite position"));
      }
      mesh->positions[3 * v + k] = position;
      if (!normal_found) continue;
      const float normal = static_cast<float>(values[layout.normal[k]]);
      if (!std::isfinite(normal)) {
        return absl::InvalidArgumentError(absl::StrCat("vertex ", v, " has a non-finite normal"));
      }
      mesh->normals[3 * v + k] = normal;
    }
  }
  return absl::OkStatus();
}

absl::Status ReadFaceElement(const PlyElement& element, size_t vertex_count, BodyReader* reader,
                             OrderedMesh* mesh) {
  FaceLayout layout;
  for (size_t i = 0; i < element.properties.size(); ++i) {
    const PlyProperty& property = element.properties[i];
    if (property.name == "vertex_indices" || property.name == "vertex_index") {
      if (!property.is_list) return absl::InvalidArgumentError("face indices are not a list");
      layout.indices = static_cast<int>(i);
    } else if (property.name == "surface" && !property.is_list) {
      layout.surface = static_cast<int>(i);
    }
  }
  if (layout.indices < 0) {
    return absl::InvalidArgumentError("face element has no vertex_indices list property");
  }

  ISOSTREAM_RETURN_IF_ERROR(reader->CheckFits(element));
  const size_t count = element.count;
  mesh->triangles.assign(3 * count, 0);
  mesh->surface.assign(count, 0);
  for (size_t f = 0; f < count; ++f) {
    for (size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      const auto truncated = [&] {
        return absl::DataLossError(
            absl::StrCat("face data ends early or is malformed at face ", f, " of ", count));
      };
      if (property.is_list) {
        double list_count;
        if (!reader->Read(property.count_type, &list_count)) return truncated();
        if (static_cast<int>(i) == layout.indices && list_count != 3) {
          return absl::InvalidArgumentError(absl::StrCat(
              "face ", f, " has ", list_count, " vertices; only triangles are supported"));
        }
        if (!IsIndexLike(list_count, 1e9)) return truncated();
        for (double k = 0; k < list_count; ++k) {
          double value;
          if (!reader->Read(property.type, &value)) return truncated();
          if (static_cast<int>(i) != layout.indices) continue;
          if (!IsIndexLike(value, static_cast<double>(vertex_count))) {
            return absl::InvalidArgumentError(absl::StrCat("face ", f, " uses vertex index ", value,
                                                           " but the file has ", vertex_count,
                                                           " vertices"));
          }
          mesh->triangles[3 * f + static_cast<size_t>(k)] = static_cast<uint32_t>(value);
        }
      } else {
        double value;
        if (!reader->Read(property.type, &value)) return truncated();
        if (static_cast<int>(i) != layout.surface) continue;
        if (!IsIndexLike(value, kMaxSurfaces)) {
          return absl::InvalidArgumentError(absl::StrCat(
              "face ", f, " has surface ", value, "; expected an integer below ", kMaxSurfaces));
        }
        mesh->surface[f] = static_cast<uint8_t>(value);
      }
    }
  }
  return absl::OkStatus();
}

absl::Status SkipElement(const PlyElement& element, BodyReader* reader) {
  for (uint64_t item = 0; item < element.count; ++item) {
    for (const PlyProperty& property : element.properties) {
      double value;
      bool ok;
      if (property.is_list) {
        ok = reader->Read(property.count_type, &value) && IsIndexLike(value, 1e9);
        const double list_count = value;
        for (double k = 0; ok && k < list_count; ++k) ok = reader->Read(property.type, &value);
      } else {
        ok = reader->Read(property.type, &value);
      }
      if (!ok) {
        return absl::DataLossError(absl::StrCat("element \"", element.name,
                                                "\" ends early or is malformed at item ", item,
                                                " of ", element.count));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status SerializePly(const OrderedMesh& mesh, bool binary, std::string* out) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateMesh(mesh));
  const bool has_normals = !mesh.normals.empty();
  const size_t vertex_count = mesh.vertex_count();
  const size_t triangle_count = mesh.triangle_count();
  *out = PlyHeader(mesh, binary);
  if (binary) {
    // Sized once and filled through a cursor: appending value by value cost ~400 instructions
    // a triangle, more than extracting it.
    const size_t header_size = out->size();
    out->resize(header_size + 24 * vertex_count + 14 * triangle_count);
    char* at = out->data() + header_size;
    const float zeros[3] = {0.0f, 0.0f, 0.0f};
    for (size_t v = 0; v < vertex_count; ++v) {
      at = PutRaw(at, &mesh.positions[3 * v], 12);
      at = PutRaw(at, has_normals ? &mesh.normals[3 * v] : zeros, 12);
    }
    for (size_t t = 0; t < triangle_count; ++t) {
      *at++ = 3;
      at = PutRaw(at, &mesh.triangles[3 * t], 12);
      *at++ = char(mesh.surface[t]);
    }
    return absl::OkStatus();
  }
  for (size_t v = 0; v < vertex_count; ++v) {
    for (int k = 0; k < 6; ++k) {
      const float value =
          k < 3 ? mesh.positions[3 * v + k] : (has_normals ? mesh.normals[3 * v + k - 3] : 0.0f);
      AppendText(out, value);
      out->push_back(k == 5 ? '\n' : ' ');
    }
  }
  for (size_t t = 0; t < triangle_count; ++t) {
    out->append("3");
    for (int k = 0; k < 3; ++k) {
      out->push_back(' ');
      AppendText(out, mesh.triangles[3 * t + k]);
    }
    out->push_back(' ');
    AppendText(out, uint32_t{mesh.surface[t]});
    out->push_back('\n');
  }
  return absl::OkStatus();
}

absl::Status WritePly(const OrderedMesh& mesh, const std::string& path, bool binary) {
  std::string bytes;
  ISOSTREAM_RETURN_IF_ERROR(PrefixStatus(path, SerializePly(mesh, binary, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::StatusOr<OrderedMesh> ParsePly(std::string_view std_bytes) {
  const absl::string_view bytes(std_bytes.data(), std_bytes.size());
  ISOSTREAM_ASSIGN_OR_RETURN(const PlyHeaderInfo header, ParseHeader(bytes));
  const PlyElement* vertex_element = nullptr;
  const PlyElement* face_element = nullptr;
  for (const PlyElement& element : header.elements) {
    if (element.name == "vertex" && !vertex_element) vertex_element = &element;
    if (element.name == "face" && !face_element) face_element = &element;
  }
  if (!vertex_element) return absl::InvalidArgumentError("PLY file has no vertex element");
  // Every stored item takes at least one byte (elements without properties are not worth
  // supporting), so a count beyond the body size is a corrupt
  // header; checking here keeps it from turning into a huge allocation.
  const size_t body_size = bytes.size() - header.data_offset;
  for (const PlyElement& element : header.elements) {
    if (element.count > body_size) {
      return absl::DataLossError(absl::StrCat("element \"", element.name, "\" declares ",
                                              element.count, " items but only ", body_size,
                                              " bytes of data follow the header"));
    }
  }

  OrderedMesh mesh;
  BodyReader reader(bytes.substr(header.data_offset), header.binary);
  for (const PlyElement& element : header.elements) {
    if (&element == vertex_element) {
      ISOSTREAM_RETURN_IF_ERROR(ReadVertexElement(element, &reader, &mesh));
    } else if (&element == face_element) {
      ISOSTREAM_RETURN_IF_ERROR(ReadFaceElement(element, vertex_element->count, &reader, &mesh));
    } else {
      ISOSTREAM_RETURN_IF_ERROR(SkipElement(element, &reader));
    }
  }
  if (!reader.OnlySpaceLeft())
    return absl::DataLossError("text follows the last element the header declares");
  return mesh;
}

absl::StatusOr<OrderedMesh> ReadPly(const std::string& path) {
  ISOSTREAM_ASSIGN_OR_RETURN(const std::string bytes, ReadFileBytes(path));
  absl::StatusOr<OrderedMesh> mesh = ParsePly(bytes);
  if (!mesh.ok()) return PrefixStatus(path, mesh.status());
  return mesh;
}

}  // namespace isostream
