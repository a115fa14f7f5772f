#include "toollib/mesh.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <ostream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/toollib/test_util.h"

namespace toolbench::toollib {
namespace {

using ::testing::AllOf;
using testing::FreshTempDir;
using ::testing::HasSubstr;
using testing::MeshData;
using ::testing::ThrowsMessage;

constexpr double kCoordTol = 1e-6;   // float STL vs decimal text [m]
constexpr double kVolumeTol = 1e-9;  // [m^3]
constexpr double kSide = 0.1;        // the fixture cube's side [m]

// The surface as a sorted list of triangles, each rotated to start at its smallest corner
// (orientation kept), coordinates rounded to micrometres: equal for equal surfaces whatever
// the vertex numbering.
std::vector<std::array<long long, 9>> Canonical(const TriangleMesh& mesh) {
  std::vector<std::array<long long, 9>> out;
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    std::array<std::array<long long, 3>, 3> corners{};
    for (int k = 0; k < 3; ++k) {
      for (int d = 0; d < 3; ++d) {
        corners[static_cast<std::size_t>(k)][static_cast<std::size_t>(d)] =
            std::llround(mesh.vertices(d, mesh.faces(k, f)) / kCoordTol);
      }
    }
    const auto first = std::min_element(corners.begin(), corners.end());
    std::rotate(corners.begin(), first, corners.end());
    std::array<long long, 9> flat{};
    for (std::size_t i = 0; i < 9; ++i) {
      flat[i] = corners[i / 3][i % 3];
    }
    out.push_back(flat);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TriangleMesh Cube(const Eigen::Vector3d& corner, double side) {
  TriangleMesh mesh;
  mesh.vertices.resize(3, 8);
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.col(i) = corner + side * Eigen::Vector3d(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  }
  mesh.faces.resize(3, 12);
  mesh.faces << 0, 0, 4, 4, 0, 0, 2, 2, 0, 0, 1, 1,  //
      2, 3, 5, 7, 1, 5, 6, 7, 4, 6, 3, 7,            //
      3, 1, 7, 6, 5, 4, 7, 3, 6, 2, 7, 5;
  return mesh;
}

TEST(MeshReaderTest, AllFormatsGiveTheSameCube) {
  const TriangleMesh reference = ReadMesh(MeshData("cube.obj"));
  for (const char* name :
       {"cube_ascii.stl", "cube_binary.stl", "cube.obj", "cube_ascii.ply", "cube_binary.ply"}) {
    SCOPED_TRACE(name);
    const TriangleMesh mesh = ReadMesh(MeshData(name));
    EXPECT_EQ(mesh.vertices.cols(), 8);  // STL corners welded back into 8 vertices
    EXPECT_EQ(mesh.faces.cols(), 12);    // quads fan-triangulated
    const MeshReport report = ValidateMesh(mesh);
    EXPECT_TRUE(report.valid) << (report.problems.empty() ? "" : report.problems.front());
    EXPECT_EQ(report.num_components, 1);
    EXPECT_NEAR(Volume(mesh), kSide * kSide * kSide, kVolumeTol);
    EXPECT_EQ(Canonical(mesh), Canonical(reference));
  }
}

TEST(MeshReaderTest, BinaryStlWhoseHeaderStartsWithSolid) {
  std::ifstream in(MeshData("cube_binary.stl"), std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  bytes.replace(0, 10, "solid cube");
  const auto path = FreshTempDir() / "solid_header.stl";
  std::ofstream(path, std::ios::binary) << bytes;
  EXPECT_EQ(Canonical(ReadMesh(path)), Canonical(ReadMesh(MeshData("cube.obj"))));
}

TEST(MeshGeometryTest, CubeMeasures) {
  const TriangleMesh cube = Cube(Eigen::Vector3d(1.0, 2.0, 3.0), kSide);
  EXPECT_NEAR(Volume(cube), 1e-3, 1e-15);
  EXPECT_NEAR(SurfaceArea(cube), 0.06, 1e-15);
  EXPECT_TRUE(Centroid(cube).isApprox(Eigen::Vector3d(1.05, 2.05, 3.05), 1e-12));
  const Eigen::AlignedBox3d box = Bounds(cube);
  EXPECT_TRUE(box.min().isApprox(Eigen::Vector3d(1.0, 2.0, 3.0)));
  EXPECT_TRUE(box.max().isApprox(Eigen::Vector3d(1.1, 2.1, 3.1)));
  EXPECT_TRUE(ValidateMesh(cube).valid);
  EXPECT_FALSE(HasSelfIntersections(cube));
}

TEST(MeshWriterTest, StlAndPlyRoundTrip) {
  const TriangleMesh cube = Cube(Eigen::Vector3d(-0.05, 0.01, 0.0), kSide);
  const auto dir = FreshTempDir();
  WriteStlBinary(dir / "cube.stl", cube);
  WritePly(dir / "cube.ply", cube);
  const TriangleMesh from_stl = ReadMesh(dir / "cube.stl");
  const TriangleMesh from_ply = ReadMesh(dir / "cube.ply");
  EXPECT_EQ(Canonical(from_stl), Canonical(cube));
  // PLY keeps numbering and full double precision.
  EXPECT_EQ(from_ply.faces, cube.faces);
  EXPECT_EQ(from_ply.vertices, cube.vertices);
}

// Each malformed file must throw naming the file and the defect.
struct BadFile {
  const char* file;
  const char* problem;
};

void PrintTo(const BadFile& bad, std::ostream* out) { *out << bad.file; }

class MalformedMeshTest : public ::testing::TestWithParam<BadFile> {};

TEST_P(MalformedMeshTest, ThrowsNamingFileAndProblem) {
  const auto path = MeshData(std::string("bad/") + GetParam().file);
  EXPECT_THAT([&] { RequireValidMesh(ReadMesh(path), path.string()); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr(GetParam().file), HasSubstr(GetParam().problem))));
}

INSTANTIATE_TEST_SUITE_P(
    BadFiles, MalformedMeshTest,
    ::testing::Values(BadFile{"truncated.stl", "truncated binary STL"},
                      BadFile{"empty.stl", "empty file"},
                      BadFile{"index_out_of_range.obj", "face index out of range"},
                      BadFile{"nan_vertex.ply", "non-finite (NaN or infinite) coordinate"},
                      BadFile{"open_box.obj", "used by one face only (hole)"},
                      BadFile{"inverted.obj", "inverted orientation"},
                      BadFile{"cube_mm.stl",
                              "looks like millimetres (diagonal 173 m); scale by 0.001"}),
    [](const ::testing::TestParamInfo<BadFile>& info) {
      std::string name = info.param.file;
      std::replace_if(
          name.begin(), name.end(), [](unsigned char c) { return !std::isalnum(c); }, '_');
      return name;
    });

TEST(MeshReaderTest, RejectsUnknownExtensionAndMissingFile) {
  const auto dir = FreshTempDir();
  std::ofstream(dir / "cube.off") << "OFF\n";
  EXPECT_THAT([&] { ReadMesh(dir / "cube.off"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("cube.off"), HasSubstr("unknown mesh extension"))));
  EXPECT_THAT([&] { ReadMesh(dir / "nothing.stl"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("nothing.stl"), HasSubstr("cannot open"))));
}

TEST(MeshReaderTest, RejectsTextDefects) {
  const auto dir = FreshTempDir();
  const auto expect_throw = [&](const std::string& name, const std::string& text,
                                const std::string& problem) {
    std::ofstream(dir / name, std::ios::binary) << text;
    EXPECT_THAT([&] { ReadMesh(dir / name); },
                ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr(name), HasSubstr(problem))));
  };
  expect_throw("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "index 0 is invalid");
  expect_throw("rel.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", "face index out of range");
  expect_throw("inf.obj", "v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite");
  expect_throw("two.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3 vertices");
  expect_throw("noface.obj", "v 0 0 0\n", "no faces");
  expect_throw("junk.obj", "v 0 0 0\nbogus 1\n", "unknown statement 'bogus'");
  expect_throw("cut.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n",
               "expected 'vertex'");
  expect_throw("nanstl.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex nan 0 0\n",
               "non-finite");
  expect_throw("big.ply",
               "ply\nformat ascii 1.0\nelement vertex 1000000\nproperty float x\n"
               "property float y\nproperty float z\nelement face 1\n"
               "property list uchar int vertex_indices\nend_header\n0 0 0\n",
               "truncated ASCII PLY");
  expect_throw("be.ply", "ply\nformat binary_big_endian 1.0\nend_header\n", "not supported");
  expect_throw("noply.ply", "plx\n", "not a PLY file");
}

TEST(MeshValidationTest, CountsEachDefect) {
  const TriangleMesh cube = Cube(Eigen::Vector3d::Zero(), kSide);

  TriangleMesh open = cube;
  open.faces.conservativeResize(3, 11);
  const MeshReport open_report = ValidateMesh(open);
  EXPECT_FALSE(open_report.valid);
  EXPECT_EQ(open_report.boundary_edges, 3);

  TriangleMesh flipped = cube;
  flipped.faces.col(0).reverseInPlace();
  EXPECT_EQ(ValidateMesh(flipped).misoriented_edges, 3);

  TriangleMesh inverted = cube;
  inverted.faces.row(1).swap(inverted.faces.row(2));
  const MeshReport inverted_report = ValidateMesh(inverted);
  EXPECT_LT(inverted_report.volume, 0.0);
  EXPECT_THAT(inverted_report.problems, ::testing::Contains(HasSubstr("inverted orientation")));

  TriangleMesh degenerate = cube;
  degenerate.faces.col(0) << 0, 0, 1;
  EXPECT_GE(ValidateMesh(degenerate).degenerate_faces, 1);

  TriangleMesh bad_index = cube;
  bad_index.faces(2, 5) = 8;
  EXPECT_EQ(ValidateMesh(bad_index).bad_indices, 1);
  EXPECT_THAT([&] { Volume(bad_index); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("Volume: face indices")));

  TriangleMesh nan_vertex = cube;
  nan_vertex.vertices(1, 3) = std::nan("");
  EXPECT_EQ(ValidateMesh(nan_vertex).nonfinite_vertices, 1);

  EXPECT_FALSE(ValidateMesh(TriangleMesh{}).valid);

  // Two cubes touching at one corner: edges are fine, the shared vertex is not.
  const TriangleMesh other = Cube(Eigen::Vector3d::Constant(kSide), kSide);
  TriangleMesh touching;
  touching.vertices.resize(3, 15);
  touching.vertices << cube.vertices, other.vertices.rightCols(7);
  touching.faces.resize(3, 24);
  Eigen::Matrix3Xi other_faces = other.faces;
  for (Eigen::Index i = 0; i < other_faces.size(); ++i) {
    int& v = other_faces.data()[i];
    v = v == 0 ? 7 : v + 7;  // other's corner 0 is cube's corner 7
  }
  touching.faces << cube.faces, other_faces;
  const MeshReport touching_report = ValidateMesh(touching);
  EXPECT_EQ(touching_report.nonmanifold_vertices, 1);
  EXPECT_EQ(touching_report.boundary_edges, 0);
  EXPECT_FALSE(touching_report.valid);

  // Millimetre and centimetre scale.
  TriangleMesh cm = cube;
  cm.vertices *= 100.0;
  EXPECT_THAT(ValidateMesh(cm).problems, ::testing::Contains(HasSubstr("looks like centimetres")));
  TriangleMesh tiny = cube;
  tiny.vertices *= 0.01;
  EXPECT_THAT(ValidateMesh(tiny).problems, ::testing::Contains(HasSubstr("implausible size")));
}

TEST(MeshValidationTest, SelfIntersectionOfOverlappingShells) {
  const TriangleMesh a = Cube(Eigen::Vector3d::Zero(), kSide);
  const TriangleMesh b = Cube(Eigen::Vector3d(0.05, 0.03, 0.02), kSide);
  TriangleMesh both;
  both.vertices.resize(3, 16);
  both.vertices << a.vertices, b.vertices;
  both.faces.resize(3, 24);
  both.faces << a.faces, (b.faces.array() + 8).matrix();
  const MeshReport report = ValidateMesh(both);
  EXPECT_TRUE(report.valid);  // two closed shells: only the intersection test sees the overlap
  EXPECT_EQ(report.num_components, 2);
  EXPECT_TRUE(HasSelfIntersections(both));
}

}  // namespace
}  // namespace toolbench::toollib
