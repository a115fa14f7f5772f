// Strict readers and writers for STL, OBJ and PLY. Our own parsers rather than CGAL's IO:
// they must reject every malformed file with a message naming the file and the defect, and
// they are fuzzed (fuzz/mesh_loader_fuzz.cpp), so they never trust a count before checking
// it against the bytes that are actually there.
#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "common/check.h"
#include "toollib/mesh.h"

namespace toolbench::toollib {
namespace {

constexpr std::size_t kStlHeaderBytes = 80;
constexpr std::size_t kStlPreambleBytes = 84;  // header + uint32 triangle count
constexpr std::size_t kStlTriangleBytes = 50;  // normal, 3 vertices (12 floats), uint16
// Beyond any tool mesh; stops a corrupt header from asking for gigabytes.
constexpr std::uint64_t kMaxElements = 50'000'000;

// Reports a defect of the file being read: "<file>: <what>".
class FileError {
 public:
  explicit FileError(const std::filesystem::path& path) : name_(path.string()) {}
  template <typename... Parts>
  [[noreturn]] void operator()(Parts&&... parts) const {
    ThrowInvalid(name_, ": ", std::forward<Parts>(parts)...);
  }

 private:
  std::string name_;
};

std::string ReadBytes(const std::filesystem::path& path, const FileError& fail) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    fail("cannot open file");
  }
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) {
    fail("read error");
  }
  if (bytes.empty()) {
    fail("empty file");
  }
  return bytes;
}

std::uint64_t LoadLittleEndian(const char* p, int num_bytes) {
  std::uint64_t value = 0;
  for (int i = num_bytes - 1; i >= 0; --i) {
    value = (value << 8) | static_cast<unsigned char>(p[i]);
  }
  return value;
}

float LoadFloat(const char* p) {
  const auto bits = static_cast<std::uint32_t>(LoadLittleEndian(p, 4));
  float value = 0.0f;
  std::memcpy(&value, &bits, sizeof(value));
  return value;
}

void StoreLittleEndian(std::uint64_t value, int num_bytes, std::string& out) {
  for (int i = 0; i < num_bytes; ++i) {
    out.push_back(static_cast<char>((value >> (8 * i)) & 0xffu));
  }
}

void StoreFloat(float value, std::string& out) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof(bits));
  StoreLittleEndian(bits, 4, out);
}

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

// Parses a whole token as a finite or non-finite double; false when it is not a number.
bool ParseDouble(std::string_view token, double& value) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
  }
  if (token.empty()) {
    return false;
  }
  const auto result = std::from_chars(token.data(), token.data() + token.size(), value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

bool ParseInt64(std::string_view token, std::int64_t& value) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
  }
  if (token.empty()) {
    return false;
  }
  const auto result = std::from_chars(token.data(), token.data() + token.size(), value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

// Whitespace tokenizer that knows the line of each token.
class Tokenizer {
 public:
  explicit Tokenizer(std::string_view text) : text_(text) {}

  // Next token, or empty at the end of the text.
  std::string_view Next() {
    SkipSpace();
    const std::size_t begin = pos_;
    while (pos_ < text_.size() && !IsSpace(text_[pos_])) {
      ++pos_;
    }
    return text_.substr(begin, pos_ - begin);
  }

  // Skips the rest of the current line (after a token).
  void SkipLine() {
    while (pos_ < text_.size() && text_[pos_] != '\n') {
      ++pos_;
    }
  }

  bool AtEnd() {
    SkipSpace();
    return pos_ >= text_.size();
  }

  int line() const { return line_; }
  std::size_t position() const { return pos_; }

 private:
  void SkipSpace() {
    while (pos_ < text_.size() && IsSpace(text_[pos_])) {
      if (text_[pos_] == '\n') {
        ++line_;
      }
      ++pos_;
    }
  }

  std::string_view text_;
  std::size_t pos_ = 0;
  int line_ = 1;
};

// Merges corners with bit-for-bit equal positions (and +0 == -0) into shared vertices,
// numbered in order of first appearance so that a written-then-read mesh keeps its order.
TriangleMesh WeldSoup(const std::vector<std::array<double, 3>>& corners) {
  TOOLBENCH_DEMAND(corners.size() % 3 == 0);
  std::vector<std::size_t> order(corners.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return corners[a] < corners[b] || (corners[a] == corners[b] && a < b);
  });
  // first_corner[c] = smallest corner index with the same position as c.
  std::vector<std::size_t> first_corner(corners.size());
  for (std::size_t i = 0; i < order.size();) {
    std::size_t j = i;
    while (j < order.size() && corners[order[j]] == corners[order[i]]) {
      first_corner[order[j]] = order[i];
      ++j;
    }
    i = j;
  }
  std::vector<int> vertex_of_corner(corners.size(), -1);
  int num_vertices = 0;
  for (std::size_t c = 0; c < corners.size(); ++c) {
    if (first_corner[c] == c) {
      vertex_of_corner[c] = num_vertices++;
    }
  }
  TriangleMesh mesh;
  mesh.vertices.resize(3, num_vertices);
  mesh.faces.resize(3, static_cast<Eigen::Index>(corners.size() / 3));
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const int v = vertex_of_corner[first_corner[c]];
    mesh.faces(static_cast<Eigen::Index>(c % 3), static_cast<Eigen::Index>(c / 3)) = v;
    if (first_corner[c] == c) {
      mesh.vertices.col(v) << corners[c][0], corners[c][1], corners[c][2];
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------------- STL

bool LooksLikeText(std::string_view bytes) {
  const std::size_t n = std::min<std::size_t>(bytes.size(), 512);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(bytes[i]);
    if (c < 0x20 && !IsSpace(static_cast<char>(c))) {
      return false;
    }
    if (c == 0x7f) {
      return false;
    }
  }
  return true;
}

TriangleMesh ReadStlBinary(const std::string& bytes, const FileError& fail) {
  if (bytes.size() < kStlPreambleBytes) {
    fail("truncated binary STL: ", bytes.size(), " bytes, shorter than the ", kStlPreambleBytes,
         "-byte header");
  }
  const std::uint64_t count = LoadLittleEndian(bytes.data() + kStlHeaderBytes, 4);
  const std::uint64_t expected = kStlPreambleBytes + kStlTriangleBytes * count;
  if (bytes.size() < expected) {
    fail("truncated binary STL: header declares ", count, " triangles (", expected,
         " bytes) but the file has ", bytes.size(), " bytes");
  }
  if (bytes.size() > expected) {
    fail("bad triangle count in binary STL: header declares ", count, " triangles (", expected,
         " bytes) but the file has ", bytes.size(), " bytes");
  }
  if (count == 0) {
    fail("binary STL has no triangles");
  }
  std::vector<std::array<double, 3>> corners;
  corners.reserve(count * 3);
  for (std::uint64_t t = 0; t < count; ++t) {
    const char* record = bytes.data() + kStlPreambleBytes + kStlTriangleBytes * t;
    for (int k = 0; k < 3; ++k) {
      std::array<double, 3> p{};
      for (int d = 0; d < 3; ++d) {
        p[static_cast<std::size_t>(d)] = LoadFloat(record + 12 + 12 * k + 4 * d);
        if (!std::isfinite(p[static_cast<std::size_t>(d)])) {
          fail("non-finite (NaN or infinite) coordinate in triangle ", t);
        }
      }
      corners.push_back(p);
    }
  }
  return WeldSoup(corners);
}

TriangleMesh ReadStlAscii(const std::string& bytes, const FileError& fail) {
  Tokenizer tok(bytes);
  const auto expect = [&](std::string_view want) {
    const std::string_view got = tok.Next();
    if (got != want) {
      fail("ASCII STL line ", tok.line(), ": expected '", want, "', found '",
           got.empty() ? std::string_view("end of file") : got, "'");
    }
  };
  const auto number = [&]() {
    const std::string_view token = tok.Next();
    double value = 0.0;
    if (!ParseDouble(token, value)) {
      fail("ASCII STL line ", tok.line(), ": expected a number, found '",
           token.empty() ? std::string_view("end of file") : token, "'");
    }
    if (!std::isfinite(value)) {
      fail("ASCII STL line ", tok.line(), ": non-finite (NaN or infinite) coordinate '", token,
           "'");
    }
    return value;
  };

  std::vector<std::array<double, 3>> corners;
  bool any_solid = false;
  while (!tok.AtEnd()) {
    expect("solid");
    tok.SkipLine();  // the solid's name
    any_solid = true;
    while (true) {
      const std::string_view keyword = tok.Next();
      if (keyword == "endsolid") {
        tok.SkipLine();
        break;
      }
      if (keyword != "facet") {
        fail("ASCII STL line ", tok.line(), ": expected 'facet' or 'endsolid', found '",
             keyword.empty() ? std::string_view("end of file") : keyword, "'");
      }
      expect("normal");
      for (int d = 0; d < 3; ++d) {
        number();  // recomputed from the vertices; never trusted
      }
      expect("outer");
      expect("loop");
      for (int k = 0; k < 3; ++k) {
        expect("vertex");
        std::array<double, 3> p{};
        for (double& x : p) {
          x = number();
        }
        corners.push_back(p);
      }
      expect("endloop");
      expect("endfacet");
      if (corners.size() / 3 > kMaxElements) {
        fail("more than ", kMaxElements, " triangles");
      }
    }
  }
  if (!any_solid || corners.empty()) {
    fail("ASCII STL has no triangles");
  }
  return WeldSoup(corners);
}

TriangleMesh ReadStl(const std::string& bytes, const FileError& fail) {
  if (bytes.size() >= kStlPreambleBytes) {
    const std::uint64_t count = LoadLittleEndian(bytes.data() + kStlHeaderBytes, 4);
    if (bytes.size() == kStlPreambleBytes + kStlTriangleBytes * count) {
      return ReadStlBinary(bytes, fail);
    }
  }
  // Binary headers may also start with "solid"; text files contain no control bytes.
  std::size_t start = 0;
  while (start < bytes.size() && IsSpace(bytes[start])) {
    ++start;
  }
  if (bytes.compare(start, 5, "solid") == 0 && LooksLikeText(bytes)) {
    return ReadStlAscii(bytes, fail);
  }
  return ReadStlBinary(bytes, fail);
}

// ---------------------------------------------------------------------------------- OBJ

TriangleMesh ReadObj(const std::string& bytes, const FileError& fail) {
  std::vector<Eigen::Vector3d> vertices;
  struct Corner {
    std::int64_t index;  // 0-based, maybe not yet checked against the vertex count
    int line;
  };
  std::vector<Corner> corners;  // 3 per triangle
  std::vector<std::int64_t> polygon;
  std::vector<std::string_view> tokens;

  std::string_view text(bytes);
  int line_number = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) {
      end = text.size();
    }
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_number;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    tokens.clear();
    Tokenizer tok(line);
    for (std::string_view t = tok.Next(); !t.empty(); t = tok.Next()) {
      tokens.push_back(t);
    }
    if (tokens.empty()) {
      continue;
    }
    const std::string_view keyword = tokens.front();
    if (keyword == "v") {
      const std::size_t n = tokens.size() - 1;
      if (n != 3 && n != 4 && n != 6) {
        fail("OBJ line ", line_number, ": vertex needs x y z [w] or x y z r g b, got ", n,
             " values");
      }
      std::array<double, 4> v{0.0, 0.0, 0.0, 1.0};
      for (std::size_t i = 0; i < std::min<std::size_t>(n, 4); ++i) {
        if (!ParseDouble(tokens[i + 1], v[i])) {
          fail("OBJ line ", line_number, ": bad number '", tokens[i + 1], "'");
        }
      }
      for (std::size_t i = 4; i < n; ++i) {  // colours: validated, unused
        double colour = 0.0;
        if (!ParseDouble(tokens[i + 1], colour)) {
          fail("OBJ line ", line_number, ": bad number '", tokens[i + 1], "'");
        }
      }
      if (!(std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]) &&
            std::isfinite(v[3]))) {
        fail("OBJ line ", line_number, ": non-finite (NaN or infinite) vertex coordinate");
      }
      if (v[3] == 0.0) {
        fail("OBJ line ", line_number, ": vertex weight w is 0");
      }
      vertices.emplace_back(v[0] / v[3], v[1] / v[3], v[2] / v[3]);
      if (vertices.size() > kMaxElements) {
        fail("more than ", kMaxElements, " vertices");
      }
    } else if (keyword == "f") {
      if (tokens.size() < 4) {
        fail("OBJ line ", line_number, ": face needs at least 3 vertices, got ", tokens.size() - 1);
      }
      polygon.clear();
      for (std::size_t i = 1; i < tokens.size(); ++i) {
        // "a", "a/b", "a//c" or "a/b/c": only the position index a matters.
        const std::string_view ref = tokens[i].substr(0, tokens[i].find('/'));
        std::int64_t index = 0;
        if (!ParseInt64(ref, index)) {
          fail("OBJ line ", line_number, ": bad vertex reference '", tokens[i], "'");
        }
        const auto count = static_cast<std::int64_t>(vertices.size());
        if (index == 0) {
          fail("OBJ line ", line_number, ": vertex index 0 is invalid (indices start at 1)");
        }
        if (index < 0) {
          if (index < -count) {
            fail("OBJ line ", line_number, ": face index out of range: relative index ", index,
                 " but only ", count, " vertices precede it");
          }
          index = count + index;
        } else {
          index = index - 1;  // checked once all vertices are known
        }
        polygon.push_back(index);
      }
      for (std::size_t i = 1; i + 1 < polygon.size(); ++i) {
        corners.push_back({polygon[0], line_number});
        corners.push_back({polygon[i], line_number});
        corners.push_back({polygon[i + 1], line_number});
      }
      if (corners.size() / 3 > kMaxElements) {
        fail("more than ", kMaxElements, " faces");
      }
    } else if (keyword == "vt" || keyword == "vn" || keyword == "vp" || keyword == "o" ||
               keyword == "g" || keyword == "s" || keyword == "usemtl" || keyword == "mtllib" ||
               keyword == "l" || keyword == "p") {
      continue;  // texture, normals, grouping, materials, lines and points: not geometry
    } else {
      fail("OBJ line ", line_number, ": unknown statement '", keyword, "'");
    }
  }
  if (corners.empty()) {
    fail("OBJ has no faces");
  }
  const auto count = static_cast<std::int64_t>(vertices.size());
  TriangleMesh mesh;
  mesh.vertices.resize(3, static_cast<Eigen::Index>(vertices.size()));
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    mesh.vertices.col(static_cast<Eigen::Index>(i)) = vertices[i];
  }
  mesh.faces.resize(3, static_cast<Eigen::Index>(corners.size() / 3));
  for (std::size_t c = 0; c < corners.size(); ++c) {
    if (corners[c].index >= count) {
      fail("OBJ line ", corners[c].line, ": face index out of range: vertex ", corners[c].index + 1,
           " but the file has ", count, " vertices");
    }
    mesh.faces(static_cast<Eigen::Index>(c % 3), static_cast<Eigen::Index>(c / 3)) =
        static_cast<int>(corners[c].index);
  }
  return mesh;
}

// ---------------------------------------------------------------------------------- PLY

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool ParsePlyType(std::string_view name, PlyType& type) {
  static constexpr std::array<std::pair<std::string_view, PlyType>, 16> kNames{{
      {"char", PlyType::kInt8},
      {"int8", PlyType::kInt8},
      {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},
      {"short", PlyType::kInt16},
      {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},
      {"uint16", PlyType::kUint16},
      {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},
      {"uint", PlyType::kUint32},
      {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},
      {"float32", PlyType::kFloat32},
      {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64},
  }};
  for (const auto& [n, t] : kNames) {
    if (n == name) {
      type = t;
      return true;
    }
  }
  return false;
}

int PlySize(PlyType type) {
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
  return 0;
}

bool IsInteger(PlyType type) { return type != PlyType::kFloat32 && type != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;  // lists only
  PlyType type = PlyType::kFloat32;      // scalar type, or list item type
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

// Reads PLY element values from either encoding, checking every read against the data left.
class PlyReader {
 public:
  PlyReader(std::string_view data, bool binary, const FileError& fail)
      : data_(data), binary_(binary), tok_(data), fail_(fail) {}

  double ReadNumber(PlyType type, std::string_view what) {
    if (binary_) {
      const int size = PlySize(type);
      if (pos_ + static_cast<std::size_t>(size) > data_.size()) {
        fail_("truncated binary PLY: data ends while reading ", what);
      }
      const std::uint64_t raw = LoadLittleEndian(data_.data() + pos_, size);
      pos_ += static_cast<std::size_t>(size);
      switch (type) {
        case PlyType::kInt8:
          return static_cast<std::int8_t>(raw);
        case PlyType::kUint8:
          return static_cast<std::uint8_t>(raw);
        case PlyType::kInt16:
          return static_cast<std::int16_t>(raw);
        case PlyType::kUint16:
          return static_cast<std::uint16_t>(raw);
        case PlyType::kInt32:
          return static_cast<std::int32_t>(raw);
        case PlyType::kUint32:
          return static_cast<std::uint32_t>(raw);
        case PlyType::kFloat32: {
          const auto bits = static_cast<std::uint32_t>(raw);
          float value = 0.0f;
          std::memcpy(&value, &bits, sizeof(value));
          return value;
        }
        case PlyType::kFloat64: {
          double value = 0.0;
          std::memcpy(&value, &raw, sizeof(value));
          return value;
        }
      }
      return 0.0;
    }
    const std::string_view token = tok_.Next();
    if (token.empty()) {
      fail_("truncated ASCII PLY: data ends while reading ", what);
    }
    if (IsInteger(type)) {
      std::int64_t value = 0;
      if (!ParseInt64(token, value)) {
        fail_("ASCII PLY line ", tok_.line(), ": expected an integer for ", what, ", found '",
              token, "'");
      }
      const int bits = 8 * PlySize(type);
      const bool is_signed =
          type == PlyType::kInt8 || type == PlyType::kInt16 || type == PlyType::kInt32;
      const std::int64_t lo = is_signed ? -(std::int64_t{1} << (bits - 1)) : 0;
      const std::int64_t hi =
          is_signed ? (std::int64_t{1} << (bits - 1)) - 1 : (std::int64_t{1} << bits) - 1;
      if (value < lo || value > hi) {
        fail_("ASCII PLY line ", tok_.line(), ": value ", value, " out of range for ", what);
      }
      return static_cast<double>(value);
    }
    double value = 0.0;
    if (!ParseDouble(token, value)) {
      fail_("ASCII PLY line ", tok_.line(), ": expected a number for ", what, ", found '", token,
            "'");
    }
    return value;
  }

  // Bytes (binary) or characters (ASCII) left; bounds how many elements can follow.
  std::size_t Remaining() const {
    const std::size_t used = binary_ ? pos_ : tok_.position();
    return data_.size() - std::min(used, data_.size());
  }

  bool AtEnd() { return binary_ ? pos_ >= data_.size() : tok_.AtEnd(); }

 private:
  std::string_view data_;
  bool binary_;
  std::size_t pos_ = 0;  // binary cursor
  Tokenizer tok_;        // ASCII cursor
  const FileError& fail_;
};

TriangleMesh ReadPly(const std::string& bytes, const FileError& fail) {
  // Header: lines up to "end_header".
  std::vector<PlyElement> elements;
  bool binary = false;
  bool have_format = false;
  std::size_t pos = 0;
  int line_number = 0;
  bool header_done = false;
  while (!header_done) {
    if (pos >= bytes.size()) {
      fail("PLY header has no 'end_header'");
    }
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) {
      end = bytes.size();
    }
    std::string_view line(bytes.data() + pos, end - pos);
    pos = std::min(end + 1, bytes.size());
    ++line_number;
    if (!line.empty() && line.back() == '\r') {
      line.remove_suffix(1);
    }
    std::vector<std::string_view> tokens;
    Tokenizer tok(line);
    for (std::string_view t = tok.Next(); !t.empty(); t = tok.Next()) {
      tokens.push_back(t);
    }
    if (line_number == 1) {
      if (tokens.size() != 1 || tokens[0] != "ply") {
        fail("not a PLY file (first line is not 'ply')");
      }
      continue;
    }
    if (tokens.empty()) {
      continue;
    }
    const std::string_view keyword = tokens[0];
    if (keyword == "comment" || keyword == "obj_info") {
      continue;
    }
    if (keyword == "format") {
      if (tokens.size() != 3 || tokens[2] != "1.0") {
        fail("PLY header line ", line_number, ": expected 'format <encoding> 1.0'");
      }
      if (tokens[1] == "ascii") {
        binary = false;
      } else if (tokens[1] == "binary_little_endian") {
        binary = true;
      } else {
        fail("PLY format '", tokens[1], "' is not supported (use ascii or binary_little_endian)");
      }
      have_format = true;
    } else if (keyword == "element") {
      std::int64_t count = 0;
      if (tokens.size() != 3 || !ParseInt64(tokens[2], count) || count < 0) {
        fail("PLY header line ", line_number, ": expected 'element <name> <count>'");
      }
      if (static_cast<std::uint64_t>(count) > kMaxElements) {
        fail("PLY header line ", line_number, ": bad count ", count, " for element '", tokens[1],
             "'");
      }
      elements.push_back({std::string(tokens[1]), static_cast<std::uint64_t>(count), {}});
    } else if (keyword == "property") {
      if (elements.empty()) {
        fail("PLY header line ", line_number, ": property before any element");
      }
      PlyProperty property;
      if (tokens.size() == 5 && tokens[1] == "list") {
        property.is_list = true;
        if (!ParsePlyType(tokens[2], property.count_type) || !IsInteger(property.count_type) ||
            !ParsePlyType(tokens[3], property.type)) {
          fail("PLY header line ", line_number, ": bad list property types '", tokens[2], " ",
               tokens[3], "'");
        }
        property.name = std::string(tokens[4]);
      } else if (tokens.size() == 3) {
        if (!ParsePlyType(tokens[1], property.type)) {
          fail("PLY header line ", line_number, ": unknown property type '", tokens[1], "'");
        }
        property.name = std::string(tokens[2]);
      } else {
        fail("PLY header line ", line_number, ": malformed property");
      }
      elements.back().properties.push_back(property);
    } else if (keyword == "end_header") {
      header_done = true;
    } else {
      fail("PLY header line ", line_number, ": unknown keyword '", keyword, "'");
    }
  }
  if (!have_format) {
    fail("PLY header has no 'format' line");
  }

  // Locate the properties we need.
  const PlyElement* vertex_element = nullptr;
  const PlyElement* face_element = nullptr;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") {
      vertex_element = &e;
    } else if (e.name == "face") {
      face_element = &e;
    }
  }
  if (vertex_element == nullptr || vertex_element->count == 0) {
    fail("PLY has no vertices");
  }
  if (face_element == nullptr || face_element->count == 0) {
    fail("PLY has no faces");
  }
  std::array<int, 3> xyz{-1, -1, -1};
  for (std::size_t i = 0; i < vertex_element->properties.size(); ++i) {
    const PlyProperty& p = vertex_element->properties[i];
    for (int d = 0; d < 3; ++d) {
      if (p.name == std::string(1, static_cast<char>('x' + d))) {
        if (p.is_list) {
          fail("PLY vertex property '", p.name, "' must be a scalar");
        }
        xyz[static_cast<std::size_t>(d)] = static_cast<int>(i);
      }
    }
  }
  if (*std::min_element(xyz.begin(), xyz.end()) < 0) {
    fail("PLY vertex element lacks property x, y or z");
  }
  int index_property = -1;
  for (std::size_t i = 0; i < face_element->properties.size(); ++i) {
    const PlyProperty& p = face_element->properties[i];
    if (p.name == "vertex_indices" || p.name == "vertex_index") {
      if (!p.is_list || !IsInteger(p.type)) {
        fail("PLY face property '", p.name, "' must be a list of integers");
      }
      index_property = static_cast<int>(i);
    }
  }
  if (index_property < 0) {
    fail("PLY face element lacks a 'vertex_indices' list");
  }

  PlyReader reader(std::string_view(bytes).substr(pos), binary, fail);
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::int64_t> triangles;  // 3 per triangle, unchecked indices
  std::vector<std::int64_t> polygon;
  for (const PlyElement& e : elements) {
    // Every element needs at least one byte or character per property.
    if (e.count * std::max<std::size_t>(e.properties.size(), 1) > reader.Remaining()) {
      fail(binary ? "truncated binary PLY" : "truncated ASCII PLY", ": header declares ", e.count,
           " '", e.name, "' elements but only ", reader.Remaining(), " bytes of data follow");
    }
    const bool is_vertex = &e == vertex_element;
    const bool is_face = &e == face_element;
    for (std::uint64_t item = 0; item < e.count; ++item) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      for (std::size_t i = 0; i < e.properties.size(); ++i) {
        const PlyProperty& property = e.properties[i];
        if (!property.is_list) {
          const double value = reader.ReadNumber(property.type, property.name);
          for (int d = 0; d < 3; ++d) {
            if (is_vertex && xyz[static_cast<std::size_t>(d)] == static_cast<int>(i)) {
              if (!std::isfinite(value)) {
                fail("non-finite (NaN or infinite) coordinate in vertex ", item);
              }
              p[d] = value;
            }
          }
          continue;
        }
        const double length = reader.ReadNumber(property.count_type, property.name);
        if (length < 0.0 || length > static_cast<double>(reader.Remaining())) {
          fail("bad list length ", length, " in '", e.name, "' ", item);
        }
        const bool wanted = is_face && static_cast<int>(i) == index_property;
        if (wanted && length < 3) {
          fail("face ", item, " has ", length, " vertices (needs at least 3)");
        }
        polygon.clear();
        for (int k = 0; k < static_cast<int>(length); ++k) {
          const double value = reader.ReadNumber(property.type, property.name);
          if (wanted) {
            polygon.push_back(static_cast<std::int64_t>(value));
          }
        }
        for (std::size_t k = 1; wanted && k + 1 < polygon.size(); ++k) {
          triangles.insert(triangles.end(), {polygon[0], polygon[k], polygon[k + 1]});
        }
      }
      if (is_vertex) {
        vertices.push_back(p);
      }
    }
  }
  if (!reader.AtEnd()) {
    fail("PLY has ", reader.Remaining(), " bytes of trailing data after the declared elements");
  }
  if (triangles.size() / 3 > kMaxElements) {
    fail("more than ", kMaxElements, " triangles");
  }

  TriangleMesh mesh;
  mesh.vertices.resize(3, static_cast<Eigen::Index>(vertices.size()));
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    mesh.vertices.col(static_cast<Eigen::Index>(i)) = vertices[i];
  }
  const auto count = static_cast<std::int64_t>(vertices.size());
  mesh.faces.resize(3, static_cast<Eigen::Index>(triangles.size() / 3));
  for (std::size_t c = 0; c < triangles.size(); ++c) {
    if (triangles[c] < 0 || triangles[c] >= count) {
      fail("face index out of range: ", triangles[c], " in triangle ", c / 3, " but the file has ",
           count, " vertices");
    }
    mesh.faces(static_cast<Eigen::Index>(c % 3), static_cast<Eigen::Index>(c / 3)) =
        static_cast<int>(triangles[c]);
  }
  return mesh;
}

std::string LowerExtension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void RequireIndices(const TriangleMesh& mesh, const std::filesystem::path& path) {
  const auto n = mesh.vertices.cols();
  if (mesh.faces.size() > 0 && (mesh.faces.minCoeff() < 0 || mesh.faces.maxCoeff() >= n)) {
    ThrowInvalid("writing ", path.string(), ": face index outside [0, ", n, ")");
  }
}

void WriteBytes(const std::filesystem::path& path, const std::string& bytes) {
  if (path.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    throw std::runtime_error(Cat("cannot write ", path.string()));
  }
}

}  // namespace

TriangleMesh ReadMesh(const std::filesystem::path& path) {
  const FileError fail(path);
  const std::string ext = LowerExtension(path);
  if (ext != ".stl" && ext != ".obj" && ext != ".ply") {
    fail("unknown mesh extension '", ext, "' (expected .stl, .obj or .ply)");
  }
  const std::string bytes = ReadBytes(path, fail);
  if (ext == ".stl") {
    return ReadStl(bytes, fail);
  }
  if (ext == ".obj") {
    return ReadObj(bytes, fail);
  }
  return ReadPly(bytes, fail);
}

void WriteStlBinary(const std::filesystem::path& path, const TriangleMesh& mesh) {
  RequireIndices(mesh, path);
  std::string bytes;
  bytes.reserve(kStlPreambleBytes +
                kStlTriangleBytes * static_cast<std::size_t>(mesh.faces.cols()));
  std::string header = "binary STL written by toolbench (metres)";
  header.resize(kStlHeaderBytes, ' ');
  bytes += header;
  StoreLittleEndian(static_cast<std::uint64_t>(mesh.faces.cols()), 4, bytes);
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.col(mesh.faces(0, f));
    const Eigen::Vector3d b = mesh.vertices.col(mesh.faces(1, f));
    const Eigen::Vector3d c = mesh.vertices.col(mesh.faces(2, f));
    Eigen::Vector3d normal = (b - a).cross(c - a);
    const double norm = normal.norm();
    normal = norm > 0.0 ? Eigen::Vector3d(normal / norm) : Eigen::Vector3d::Zero();
    for (int d = 0; d < 3; ++d) {
      StoreFloat(static_cast<float>(normal[d]), bytes);
    }
    for (const Eigen::Vector3d* p : {&a, &b, &c}) {
      for (int d = 0; d < 3; ++d) {
        StoreFloat(static_cast<float>((*p)[d]), bytes);
      }
    }
    StoreLittleEndian(0, 2, bytes);
  }
  WriteBytes(path, bytes);
}

void WritePly(const std::filesystem::path& path, const TriangleMesh& mesh) {
  RequireIndices(mesh, path);
  std::ostringstream out;
  out.precision(17);
  out << "ply\nformat ascii 1.0\ncomment written by toolbench, metres\n"
      << "element vertex " << mesh.vertices.cols() << "\n"
      << "property double x\nproperty double y\nproperty double z\n"
      << "element face " << mesh.faces.cols() << "\n"
      << "property list uchar int vertex_indices\nend_header\n";
  for (Eigen::Index i = 0; i < mesh.vertices.cols(); ++i) {
    out << mesh.vertices(0, i) << ' ' << mesh.vertices(1, i) << ' ' << mesh.vertices(2, i) << '\n';
  }
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    out << "3 " << mesh.faces(0, f) << ' ' << mesh.faces(1, f) << ' ' << mesh.faces(2, f) << '\n';
  }
  WriteBytes(path, out.str());
}

}  // namespace toolbench::toollib
