#include "core/closest_point.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <mutex>
#include <numeric>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace flankcam {

TrianglePoint closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, {1, 0, 0}};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, {0, 1, 0}};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {a + v * ab, {1 - v, v, 0}};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, {0, 0, 1}};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {a + w * ac, {1 - w, 0, w}};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + w * (c - b), {0, 1 - w, w}};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {a + ab * v + ac * w, {1 - v - w, v, w}};
}

namespace {

// Largest distance from a point of the triangle to its nearest corner: the
// circumradius for non-obtuse triangles, half the longest edge otherwise.
double covering_radius_of(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double A = (b - c).squaredNorm(), B = (c - a).squaredNorm(), C = (a - b).squaredNorm();
  const double longest = std::max({A, B, C});
  if (2 * longest >= A + B + C) return 0.5 * std::sqrt(longest);  // right or obtuse
  const double area2 = (b - a).cross(c - a).norm();                // twice the area
  return std::sqrt(A * B * C) / (2 * area2);
}


// Oriented bounding box of a node of the binary tree that is built first: local = R (p - c),
// |local_k| <= e_k. R's rows are the principal axes of the node's vertices, so on a smooth surface
// the box is thin along the normal and the lower bound stays tight at any query distance (an
// axis-aligned box is as thick as the patch is tilted, and the number of boxes it cannot prune
// grows like √n at one tool radius off the surface).
struct Node {
  float R[9];     // rows: the principal axes, rounded to float (the extents are measured in this frame)
  float m[3];     // centre of the box in that frame
  float e[3];     // half extents, rounded up
  int link = 0;   // inner: index of the left child; leaf: ~(first slot * 8 + count)
  int right = 0;  // inner: index of the right child
  int faces = 0;  // number of faces below
  [[nodiscard]] bool leaf() const { return link < 0; }
};
constexpr double kFrameError = 1e-6;

// The searched tree: the binary tree collapsed to four children per node, their boxes side by side
// (lane j is child j) so that one pass of 4-wide float arithmetic bounds all four. The float
// bounds are made conservative by kFloatError (see Impl::search).
constexpr int kEmptyLane = std::numeric_limits<int>::min();
struct alignas(64) Node4 {
  float R[9][4];
  float m[3][4];
  float e[3][4];
  int link[4];  // >= 0: index of a Node4; kEmptyLane: no child; else leaf: ~(first slot * 8 + count)
};
static_assert(sizeof(Node4) == 256, "four cache lines per node");
constexpr double kFloatError = 1e-6;

// A face in leaf order: a copy of its corners (the same doubles as the mesh's, so the distance
// is bit-equal to brute force's), its index, and its boundary flags for the footpoint (bit k:
// edge k is a boundary edge; bit 3 + k: corner k is a boundary vertex).
struct LeafFace {
  Eigen::Vector3d a, b, c;
  int face = -1;
  int boundary = 0;
};

constexpr int kLeafFaces = 4;
constexpr size_t kCertificateLeaves = size_t(1) << 15;  // meshes of up to 131,072 faces get local certificates

// Float lower bounds on the distance from a point to each face of a leaf (lane j: face j): the
// distance to the face's plane, and in the plane the distance beyond the farthest edge line
// (u_k: the inward unit normal of edge k in the plane), |p - q|^2 >= plane^2 + beyond^2 for every
// q of the face. Lets a leaf skip most of its exact point-triangle tests.
struct alignas(64) LeafBound {
  float n[3][4], d[4];         // unit normal, n.a
  float u[3][3][4], ud[3][4];  // edge k: u_k, u_k.(corner k)
};

// Fills lane j of b for face t. A degenerate face gets zeros (bound 0: always tested exactly).
void set_lane(LeafBound& b, int j, const LeafFace& t) {
  const Eigen::Vector3d corner[3] = {t.a, t.b, t.c};
  const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a).normalized();
  Eigen::Vector3d u[3];
  for (int k = 0; k < 3; ++k) u[k] = n.cross(corner[(k + 1) % 3] - corner[k]).normalized();
  if (!n.allFinite() || !u[0].allFinite() || !u[1].allFinite() || !u[2].allFinite()) return;
  for (int i = 0; i < 3; ++i) b.n[i][j] = float(n[i]);
  b.d[j] = float(n.dot(t.a));
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < 3; ++i) b.u[k][i][j] = float(u[k][i]);
    b.ud[k][j] = float(u[k].dot(corner[k]));
  }
}

// Squared lower bounds for the four lanes, each term lowered by `margin` (the float evaluation's
// error bound for this query) before squaring.
inline void leaf_bound4(const LeafBound& b, float x, float y, float z, float margin, float* lb) {
#ifdef __SSE2__
  const __m128 X = _mm_set1_ps(x), Y = _mm_set1_ps(y), Z = _mm_set1_ps(z), M = _mm_set1_ps(margin), zero = _mm_setzero_ps();
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const auto dot = [&](const float (*v)[4], const float* d) {
    return _mm_sub_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_load_ps(v[0]), X), _mm_mul_ps(_mm_load_ps(v[1]), Y)),
                                 _mm_mul_ps(_mm_load_ps(v[2]), Z)),
                      _mm_load_ps(d));
  };
  const __m128 plane = _mm_max_ps(_mm_sub_ps(_mm_and_ps(dot(b.n, b.d), abs_mask), M), zero);
  // beyond edge k: -(u_k.p - u_k.corner_k)
  const __m128 beyond = _mm_max_ps(
      _mm_sub_ps(_mm_sub_ps(zero, _mm_min_ps(_mm_min_ps(dot(b.u[0], b.ud[0]), dot(b.u[1], b.ud[1])), dot(b.u[2], b.ud[2]))), M), zero);
  _mm_store_ps(lb, _mm_add_ps(_mm_mul_ps(plane, plane), _mm_mul_ps(beyond, beyond)));
#else
  for (int j = 0; j < 4; ++j) {
    const float plane = std::max(std::abs(b.n[0][j] * x + b.n[1][j] * y + b.n[2][j] * z - b.d[j]) - margin, 0.0F);
    float inside = INFINITY;
    for (int k = 0; k < 3; ++k) inside = std::min(inside, b.u[k][0][j] * x + b.u[k][1][j] * y + b.u[k][2][j] * z - b.ud[k][j]);
    const float beyond = std::max(-inside - margin, 0.0F);
    lb[j] = plane * plane + beyond * beyond;
  }
#endif
}

// The order both searches pick by: smaller squared distance, then the lower face index; a NaN
// distance (a degenerate triangle) counts as infinite. Updates (best2, face) and says whether f won.
inline bool closer(double d2, int f, double& best2, int& face) {
  if (std::isnan(d2)) d2 = std::numeric_limits<double>::infinity();
  if (face >= 0 && !(d2 < best2 || (d2 == best2 && f < face))) return false;
  best2 = d2;
  face = f;
  return true;
}

// The answer for a query that is not finite: no face, infinite distance, NaN point, and marked
// as beyond the boundary so that callers which skip samples off Φ's rim skip it too.
Footpoint no_footpoint() {
  Footpoint f;
  f.point = f.normal = f.barycentric = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  f.distance = std::numeric_limits<double>::infinity();
  f.face = -1;
  f.on_boundary = true;
  return f;
}

// Lower bounds on the squared distance from (x, y, z) to the four boxes of w, lowered by `margin`
// on each axis, and the order keys: the squared distance outside a box, the (negative) depth
// inside (the deeper p is in a box, the likelier it holds the footpoint).
inline void bound4(const Node4& w, float x, float y, float z, float margin, float* d2, float* key) {
#ifdef __SSE2__
  const __m128 X = _mm_set1_ps(x), Y = _mm_set1_ps(y), Z = _mm_set1_ps(z), M = _mm_set1_ps(margin);
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff)), zero = _mm_setzero_ps();
  const auto outside = [&](int k) {
    const __m128 l = _mm_sub_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_load_ps(w.R[3 * k]), X), _mm_mul_ps(_mm_load_ps(w.R[3 * k + 1]), Y)),
                                           _mm_mul_ps(_mm_load_ps(w.R[3 * k + 2]), Z)),
                                _mm_load_ps(w.m[k]));
    return _mm_sub_ps(_mm_sub_ps(_mm_and_ps(l, abs_mask), _mm_load_ps(w.e[k])), M);
  };
  const __m128 o0 = outside(0), o1 = outside(1), o2 = outside(2);
  const __m128 c0 = _mm_max_ps(o0, zero), c1 = _mm_max_ps(o1, zero), c2 = _mm_max_ps(o2, zero);
  const __m128 d = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c0, c0), _mm_mul_ps(c1, c1)), _mm_mul_ps(c2, c2));
  const __m128 depth = _mm_max_ps(o0, o1);
  const __m128 out = _mm_cmpgt_ps(d, zero);
  _mm_store_ps(d2, d);
  _mm_store_ps(key, _mm_or_ps(_mm_and_ps(out, d), _mm_andnot_ps(out, depth)));
#else
  for (int j = 0; j < 4; ++j) {
    float o[3];
    for (int k = 0; k < 3; ++k)
      o[k] = std::abs(w.R[3 * k][j] * x + w.R[3 * k + 1][j] * y + w.R[3 * k + 2][j] * z - w.m[k][j]) - w.e[k][j] - margin;
    const float c0 = std::max(o[0], 0.0F), c1 = std::max(o[1], 0.0F), c2 = std::max(o[2], 0.0F);
    d2[j] = c0 * c0 + c1 * c1 + c2 * c2;
    key[j] = d2[j] > 0 ? d2[j] : std::max(o[0], o[1]);
  }
#endif
}

// Bit j set: lane j holds a child and its bound d2[j] is within prune2.
inline int near_mask(const Node4& w, const float* d2, float prune2) {
#ifdef __SSE2__
  const int near = _mm_movemask_ps(_mm_cmple_ps(_mm_load_ps(d2), _mm_set1_ps(prune2)));
  const int empty = _mm_movemask_ps(_mm_castsi128_ps(
      _mm_cmpeq_epi32(_mm_load_si128(reinterpret_cast<const __m128i*>(w.link)), _mm_set1_epi32(kEmptyLane))));
  return near & ~empty;
#else
  int mask = 0;
  for (int j = 0; j < 4; ++j)
    if (w.link[j] != kEmptyLane && d2[j] <= prune2) mask |= 1 << j;
  return mask;
#endif
}

}  // namespace

struct SurfaceIndex::Impl {
  TriMesh mesh;
  std::vector<Eigen::Vector3d> normals;
  std::once_flag across_once;               // pseudo_normal's edge neighbours, built on first use
  std::vector<std::array<int, 3>> across;   // per face, per edge k (corners k, k+1): the other face, or -1
  MeshTopology topology;
  double cover = 0;
  std::vector<Node4> wide;                  // wide[0] is the root
  std::vector<LeafFace> tri;                // the faces in leaf order, kLeafFaces slots per leaf
  std::vector<LeafBound> bounds;            // per leaf: bounds[slot / kLeafFaces]
  double slack = 0;                         // absolute rounding allowance of the box bounds
  double coordinate_bound = 0;              // largest |coordinate| of a vertex
  BoundingBox box;                          // of the vertices (orders batch queries)
  bool prefetching = false;                 // the tree is far bigger than a core's caches
  // Local certificates (queries on or next to the surface): per leaf l, the leaves holding a face
  // that shares a corner with one of l's faces, l included (near_leaf[near_begin[l] .. near_begin[l + 1]),
  // ascending), the centre of l's corners, and `reach`: a lower bound, less 2 slack, on the distance
  // from that centre to every face outside those leaves (+inf: none).
  std::vector<int> near_begin, near_leaf;
  std::vector<double> reach;                // per leaf
  std::vector<Eigen::Vector3d> centre;      // per leaf
  // Cell grid (queries on or next to the surface, any mesh size): cubes of side grid_h from
  // grid_lo; a cell lists every leaf whose corners' axis-aligned box, widened by grid_reach, meets
  // it (cell_leaf[c.begin .. c.end), ascending). A face within grid_reach of p is in a leaf listed
  // by p's cell, so when the nearest listed face is nearer than grid_reach the search ends there,
  // without the descent from the root; a query whose cell is not stored is farther than grid_reach
  // from every face. Cells are found by open addressing on their packed coordinates.
  struct Cell {
    uint64_t key = kNoCell;
    uint32_t begin = 0, end = 0;
  };
  static constexpr uint64_t kNoCell = ~uint64_t(0);
  std::vector<Cell> cells;                  // hash table, a power of two long; empty: no grid
  std::vector<int> cell_leaf;
  Eigen::Vector3d grid_lo = Eigen::Vector3d::Zero();
  double grid_h = 0, grid_reach = 0;
  static uint64_t cell_hash(uint64_t key) {
    key ^= key >> 31;
    key *= 0x9e3779b97f4a7c15ULL;
    return key ^ (key >> 29);
  }
  // The packed coordinates of p's cell; false outside the grid (or p not finite).
  bool cell_key(const Eigen::Vector3d& p, uint64_t& key) const {
    key = 0;
    for (int k = 0; k < 3; ++k) {
      const double c = std::floor((p[k] - grid_lo[k]) / grid_h);
      if (!(c >= 0 && c < double(1 << 21))) return false;
      key = key << 21 | uint64_t(c);
    }
    return true;
  }
  // The cell of p, or nullptr when none is stored (or p is outside the grid).
  const Cell* cell_of(const Eigen::Vector3d& p) const {
    uint64_t key = 0;
    if (cells.empty() || !cell_key(p, key)) return nullptr;
    const size_t mask = cells.size() - 1;
    for (size_t i = cell_hash(key) & mask;; i = (i + 1) & mask) {
      if (cells[i].key == key) return &cells[i];
      if (cells[i].key == kNoCell) return nullptr;
    }
  }
  // A batch fetches ahead: the table slot of a later query's cell, then (the slot in cache) its
  // list and the bounds of the leaves listed.
  void prefetch_slot(const Eigen::Vector3d& p) const {
    uint64_t key = 0;
    if (!cells.empty() && cell_key(p, key)) __builtin_prefetch(&cells[cell_hash(key) & (cells.size() - 1)]);
  }
  void prefetch_cell(const Eigen::Vector3d& p) const {
    if (const Cell* c = cell_of(p)) {
      for (uint32_t k = c->begin; k < c->end; k += 16) __builtin_prefetch(&cell_leaf[k]);
      for (uint32_t k = c->begin; k < c->end; ++k) {
        const char* b = reinterpret_cast<const char*>(&bounds[size_t(cell_leaf[k])]);
        for (size_t o = 0; o < sizeof(LeafBound); o += 64) __builtin_prefetch(b + o);
      }
    }
  }
  void build_grid();

  double face_distance2(int f, const Eigen::Vector3d& p) const {
    const auto& F = mesh.faces[f];
    return (closest_on_triangle(p, mesh.vertices[F[0]], mesh.vertices[F[1]], mesh.vertices[F[2]]).point - p)
        .squaredNorm();
  }

  void build();
  // The closest face's slot in `tri` (-1: none) and its closest point.
  struct Hit {
    int slot = -1;
    TrianglePoint tp;
  };
  // `excluded`: ascending leaf indices whose faces are left out (the certificates' build); none when empty.
  Hit search(const Eigen::Vector3d& p, int hint_leaf = -1, const int* excluded_begin = nullptr,
             const int* excluded_end = nullptr) const;
  void build_certificates();
  Footpoint footpoint(const Eigen::Vector3d& p, const Hit& h) const {
    if (h.slot < 0) return no_footpoint();
    const LeafFace& T = tri[size_t(h.slot)];
    return make_footpoint(p, T.face, h.tp, T.boundary);
  }

  // The footpoint of p on face f, whose closest point is tp; `boundary` as in LeafFace.
  Footpoint make_footpoint(const Eigen::Vector3d& p, int f, const TrianglePoint& tp, int boundary) const {
    const auto& F = mesh.faces[size_t(f)];
    Footpoint fp;
    fp.point = tp.point;
    fp.barycentric = tp.barycentric;
    fp.distance = (p - tp.point).norm();
    fp.face = f;
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) n += tp.barycentric[k] * normals[size_t(F[size_t(k)])];
    fp.normal = n.norm() > 1e-12 ? Eigen::Vector3d(n.normalized()) : face_normal(mesh, f);
    // On the boundary: on a boundary edge (the opposite corner's weight is 0) or at a boundary vertex.
    for (int k = 0; k < 3; ++k) {
      const int opposite = (k + 2) % 3;
      if (tp.barycentric[opposite] == 0 && (boundary >> k & 1)) fp.on_boundary = true;
      if (tp.barycentric[k] == 1 && (boundary >> (3 + k) & 1)) fp.on_boundary = true;
    }
    return fp;
  }
  int boundary_flags(int f) const {
    int flags = 0;
    for (int k = 0; k < 3; ++k) {
      if (topology.boundary_edge[size_t(f)][size_t(k)]) flags |= 1 << k;
      if (topology.boundary_vertex[size_t(mesh.faces[size_t(f)][size_t(k)])]) flags |= 8 << k;
    }
    return flags;
  }
};

// Top-down: each node's axes are the principal axes of its faces' corners (of at most 64 faces),
// its extents are measured on all its corners (exact boxes at every level: loose upper boxes
// cost far more queries than the O(n log n) build), and it is split at the median centroid along
// its longest axis. Deterministic: the median is found on (projection, face index) pairs.
void SurfaceIndex::Impl::build() {
  const int nf = int(mesh.faces.size());
  std::vector<Node> nodes;  // the binary tree; nodes[0] is the root
  std::vector<std::pair<double, int>> order(static_cast<size_t>(nf));
  std::vector<Eigen::Vector3d> centroid(static_cast<size_t>(nf));
  double scale = 0;
  const long nv = long(mesh.vertices.size());
#pragma omp parallel for schedule(static) reduction(max : scale) if (nv > 20000)
  for (long v = 0; v < nv; ++v) scale = std::max(scale, mesh.vertices[size_t(v)].cwiseAbs().maxCoeff());
#pragma omp parallel for schedule(static) if (nf > 20000)
  for (int f = 0; f < nf; ++f) {
    const auto& F = mesh.faces[size_t(f)];
    centroid[size_t(f)] = (mesh.vertices[size_t(F[0])] + mesh.vertices[size_t(F[1])] + mesh.vertices[size_t(F[2])]) / 3;
    order[size_t(f)] = {0.0, f};
  }
  // A few thousand ulps of the largest coordinate: covers the rounding of the box bounds and of
  // the triangle distances, so a box never prunes a face brute force would pick.
  slack = 1e-12 * scale + std::numeric_limits<double>::min();
  coordinate_bound = scale;
  // Stores the frame R (rounded to float) and the extents in it of the corners of the faces
  // order[begin, end), widened for rounding.
  const auto set_box = [&](Node& node, const Eigen::Matrix3d& R, int begin, int end) {
    Eigen::Matrix3d Rf;
    for (int i = 0; i < 9; ++i) node.R[i] = float(R(i / 3, i % 3)), Rf(i / 3, i % 3) = double(node.R[i]);
    double lo0 = INFINITY, lo1 = INFINITY, lo2 = INFINITY, hi0 = -INFINITY, hi1 = -INFINITY, hi2 = -INFINITY;
    for (int k = begin; k < end; ++k)
      for (int v : mesh.faces[size_t(order[size_t(k)].second)]) {
        const Eigen::Vector3d l = Rf * mesh.vertices[size_t(v)];
        lo0 = std::min(lo0, l[0]), lo1 = std::min(lo1, l[1]), lo2 = std::min(lo2, l[2]);
        hi0 = std::max(hi0, l[0]), hi1 = std::max(hi1, l[1]), hi2 = std::max(hi2, l[2]);
      }
    const Eigen::Vector3d lo(lo0, lo1, lo2), hi(hi0, hi1, hi2);
    for (int k = 0; k < 3; ++k) {
      node.m[k] = float(0.5 * (lo[k] + hi[k]));
      const double half = std::max(hi[k] - double(node.m[k]), double(node.m[k]) - lo[k]);
      // (kFloatError |m|: the centre's share of the search's float error bound)
      const double wide = half + 4 * slack + (1e-12 + kFloatError) * std::abs(double(node.m[k]));
      node.e[k] = float(wide);
      if (double(node.e[k]) < wide) node.e[k] = std::nextafter(node.e[k], INFINITY);
    }
  };

  // Preorder layout fixed by the face counts alone: a subtree of c faces has 2 ceil(c / kLeafFaces) - 1
  // nodes (every leaf but the last is full), its left child follows it and its right child follows
  // the left subtree; a leaf's slots start at its first face's position. So every subtree's nodes
  // and slots are known before it is built, and subtrees are built in parallel with the same result.
  const int leaves = (nf + kLeafFaces - 1) / kLeafFaces;
  nodes.resize(size_t(2 * leaves - 1));
  tri.resize(size_t(leaves) * kLeafFaces);
  bounds.resize(size_t(leaves));
  struct Range {
    int node, begin, end;
  };
  // Builds the node of r and returns its children's ranges in `todo`.
  const auto step = [&](const Range r, std::vector<Range>& todo) {
    const int count = r.end - r.begin;
    nodes[size_t(r.node)].faces = count;
    const int stride = std::max(1, count / 64);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    int used = 0;
    for (int k = r.begin; k < r.end; k += stride, ++used) mean += centroid[size_t(order[size_t(k)].second)];
    mean /= double(used);
    // Principal axes of the corners (of every stride-th face: at most 64 faces per node).
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int k = r.begin; k < r.end; k += stride)
      for (int v : mesh.faces[size_t(order[size_t(k)].second)]) {
        const Eigen::Vector3d d = mesh.vertices[size_t(v)] - mean;
        cov += d * d.transpose();
      }
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // rows: axes, the first of largest spread
    if (cov.allFinite() && cov.norm() > 0) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
      eig.computeDirect(cov);
      const Eigen::Matrix3d Q = eig.eigenvectors();  // columns, ascending eigenvalues
      Eigen::Matrix3d Rn;
      Rn.row(0) = Q.col(2).normalized().transpose();
      Rn.row(1) = Q.col(1).normalized().transpose();
      Rn.row(2) = Rn.row(0).cross(Rn.row(1)).normalized();
      Rn.row(1) = Rn.row(2).cross(Rn.row(0)).normalized();
      if (Rn.allFinite()) R = Rn;
    }
    set_box(nodes[size_t(r.node)], R, r.begin, r.end);
    if (count <= kLeafFaces) {
      Node& node = nodes[size_t(r.node)];
      node.link = ~(r.begin * 8 + count);  // r.begin is a multiple of kLeafFaces
      std::sort(order.begin() + r.begin, order.begin() + r.end,
                [](const auto& x, const auto& y) { return x.second < y.second; });
      LeafBound bound;
      std::memset(&bound, 0, sizeof bound);
      for (int k = r.begin; k < r.end; ++k) {
        const int f = order[size_t(k)].second, j = k - r.begin;
        const auto& F = mesh.faces[size_t(f)];
        LeafFace t;
        t.a = mesh.vertices[size_t(F[0])], t.b = mesh.vertices[size_t(F[1])], t.c = mesh.vertices[size_t(F[2])];
        t.face = f;
        t.boundary = boundary_flags(f);
        tri[size_t(k)] = t;
        set_lane(bound, j, t);
      }
      bounds[size_t(r.begin / kLeafFaces)] = bound;
      return;
    }
    // Split at the median along the box's longest axis.
    int axis = 0;
    Eigen::Vector3f(nodes[size_t(r.node)].e[0], nodes[size_t(r.node)].e[1], nodes[size_t(r.node)].e[2]).maxCoeff(&axis);
    const Eigen::RowVector3d dir = R.row(axis);
    for (int k = r.begin; k < r.end; ++k) order[size_t(k)].first = dir.dot(centroid[size_t(order[size_t(k)].second)]);
    // The left part is a multiple of kLeafFaces, so only the last leaf is not full.
    const int mid = r.begin + kLeafFaces * ((count + kLeafFaces - 1) / kLeafFaces / 2);
    std::nth_element(order.begin() + r.begin, order.begin() + mid, order.begin() + r.end);
    const int left = r.node + 1, right = r.node + (mid - r.begin) / 2;  // 2 (mid - begin) / 4 - 1 nodes on the left
    nodes[size_t(r.node)].link = left;
    nodes[size_t(r.node)].right = right;
    todo.push_back({right, mid, r.end});
    todo.push_back({left, r.begin, mid});
  };
  // The top of the tree serially, then its subtrees of at most `grain` faces on all threads.
  const int grain = std::max(4096, nf / 64);
  std::vector<Range> todo{{0, 0, nf}}, deferred;
  while (!todo.empty()) {
    const Range r = todo.back();
    todo.pop_back();
    if (r.end - r.begin <= grain && nf > 4 * grain) deferred.push_back(r);
    else step(r, todo);
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (long i = 0; i < long(deferred.size()); ++i) {
    std::vector<Range> local{deferred[size_t(i)]};
    while (!local.empty()) {
      const Range r = local.back();
      local.pop_back();
      step(r, local);
    }
  }
  // Collapse into Node4s in depth-first order: a node's children are the binary node's children,
  // the inner one with the most faces (the first on a tie) replaced by its children until there are four.
  wide.reserve(nodes.size() / 3 + 1);
  const auto collapse = [&](const auto& self, std::vector<int> lanes) -> int {
    for (;;) {
      int expand = -1;
      if (lanes.size() < 4)
        for (int j = 0; j < int(lanes.size()); ++j)
          if (!nodes[size_t(lanes[size_t(j)])].leaf() &&
              (expand < 0 || nodes[size_t(lanes[size_t(j)])].faces > nodes[size_t(lanes[size_t(expand)])].faces))
            expand = j;
      if (expand < 0) break;
      const Node& b = nodes[size_t(lanes[size_t(expand)])];
      const int l = b.link, rc = b.right;
      lanes[size_t(expand)] = l;
      lanes.insert(lanes.begin() + expand + 1, rc);
    }
    const int index = int(wide.size());
    wide.emplace_back();
    for (int j = 0; j < 4; ++j) {
      Node4& w = wide[size_t(index)];
      if (j >= int(lanes.size())) {
        w.link[j] = kEmptyLane;
        for (int k = 0; k < 3; ++k) w.m[k][j] = 0, w.e[k][j] = 0;
        for (int k = 0; k < 9; ++k) w.R[k][j] = 0;
        continue;
      }
      const Node& b = nodes[size_t(lanes[size_t(j)])];
      for (int k = 0; k < 9; ++k) w.R[k][j] = b.R[k];
      for (int k = 0; k < 3; ++k) w.m[k][j] = b.m[k], w.e[k][j] = b.e[k];
      w.link[j] = b.leaf() ? b.link : 0;
    }
    for (int j = 0; j < int(lanes.size()); ++j)
      if (!nodes[size_t(lanes[size_t(j)])].leaf()) {
        const Node& b = nodes[size_t(lanes[size_t(j)])];
        const int child = self(self, std::vector<int>{b.link, b.right});
        wide[size_t(index)].link[j] = child;
      }
    return index;
  };
  collapse(collapse, nodes[0].leaf() ? std::vector<int>{0} : std::vector<int>{nodes[0].link, nodes[0].right});
  prefetching = wide.size() * sizeof(Node4) + bounds.size() * (sizeof(LeafBound) + kLeafFaces * sizeof(LeafFace)) > (8u << 20);
}

// The cell grid of search(): the cell side is the median extent of a leaf's box and the reach a
// tenth of it, so that a cell lists a few leaves; a mesh whose leaves vary so much in size that the
// lists would exceed kGridEntries per leaf gets coarser cells (or none). A leaf is listed by the
// cells that one of its faces, widened by the reach, may meet: those of the face's widened box
// that its widened plane passes through. Built on all threads, the same at any thread count.
void SurfaceIndex::Impl::build_grid() {
  constexpr double kGridEntries = 24, kReach = 0.1;
  const int leaves = int(bounds.size()), nf = int(mesh.faces.size());
  std::vector<double> extent(static_cast<size_t>(leaves));
  bool finite = true;
#pragma omp parallel for schedule(static) reduction(&& : finite) if (leaves > 20000)
  for (int l = 0; l < leaves; ++l) {
    Eigen::Vector3d a = Eigen::Vector3d::Constant(INFINITY), b = Eigen::Vector3d::Constant(-INFINITY);
    for (int k = l * kLeafFaces; k < std::min(nf, (l + 1) * kLeafFaces); ++k)
      for (const Eigen::Vector3d* v : {&tri[size_t(k)].a, &tri[size_t(k)].b, &tri[size_t(k)].c}) a = a.cwiseMin(*v), b = b.cwiseMax(*v);
    finite = finite && a.allFinite() && b.allFinite();
    extent[size_t(l)] = (b - a).maxCoeff();
  }
  if (!finite || leaves == 0) return;  // (a mesh with non-finite corners: no grid)
  std::nth_element(extent.begin(), extent.begin() + leaves / 2, extent.end());
  double h = extent[size_t(leaves / 2)];
  if (!(h > 1e3 * slack)) return;
  // Rounding of the widened boxes and planes: covered by a few slacks more.
  const double pad = 4 * slack;
  int leaf_bits = 1;
  while ((1L << leaf_bits) < leaves) ++leaf_bits;
  for (int attempt = 0; attempt < 4; ++attempt, h *= 2) {
    const double reach_now = kReach * h;
    const Eigen::Vector3d origin = box.min - Eigen::Vector3d::Constant(reach_now + h);
    long dim[3];
    for (int k = 0; k < 3; ++k) dim[k] = long((box.max[k] + reach_now - origin[k]) / h) + 3;
    if (std::max({dim[0], dim[1], dim[2]}) >= (1L << 21) || double(dim[0]) * double(dim[1]) * double(dim[2]) >= std::ldexp(1.0, 63 - leaf_bits))
      continue;
    // Leaf l's cells as (dense cell index << leaf_bits | l), written to out (nullptr: counted only).
    const auto leaf_cells = [&](int l, uint64_t* out) {
      uint64_t cell[64];
      int n = 0;
      long total = 0;
      for (int k = l * kLeafFaces; k < std::min(nf, (l + 1) * kLeafFaces); ++k) {
        const LeafFace& t = tri[size_t(k)];
        const Eigen::Vector3d lo = t.a.cwiseMin(t.b).cwiseMin(t.c), hi = t.a.cwiseMax(t.b).cwiseMax(t.c);
        long r[3][2];
        for (int d = 0; d < 3; ++d) {
          r[d][0] = long(std::floor((lo[d] - reach_now - pad - origin[d]) / h));
          r[d][1] = long(std::floor((hi[d] + reach_now + pad - origin[d]) / h));
          // A face meets a cell in every slice its own extent spans (the cell holding its point
          // there passes the slab test): one whose box spans 67 slices (65 without the widening)
          // cannot fit, and its box (slices cubed) is not walked (a sliver across a machined
          // surface's whole length had the walk run for minutes).
          if (r[d][1] - r[d][0] >= 66) return -1L;
        }
        const Eigen::Vector3d nrm = (t.b - t.a).cross(t.c - t.a).normalized();
        const bool slab = nrm.allFinite();
        const double half = (0.5 * h + reach_now) * nrm.cwiseAbs().sum() + 2 * pad;
        for (long i = r[0][0]; i <= r[0][1]; ++i)
          for (long j = r[1][0]; j <= r[1][1]; ++j)
            for (long m = r[2][0]; m <= r[2][1]; ++m) {
              if (slab) {
                const Eigen::Vector3d c = origin + h * Eigen::Vector3d(double(i) + 0.5, double(j) + 0.5, double(m) + 0.5);
                if (std::abs(nrm.dot(c - t.a)) > half) continue;
              }
              const uint64_t key = uint64_t((i * dim[1] + j) * dim[2] + m) << leaf_bits | uint64_t(l);
              if (n < 64) cell[n++] = key;
              if (++total > 64) return -1L;  // one leaf in over 64 cells: the cells are too small
            }
      }
      std::sort(cell, cell + n);
      n = int(std::unique(cell, cell + n) - cell);
      if (out) std::copy(cell, cell + n, out);
      return long(n);
    };
    std::vector<long> first(size_t(leaves) + 1, 0);
    bool fits = true;
#pragma omp parallel for schedule(static) reduction(&& : fits) if (leaves > 20000)
    for (int l = 0; l < leaves; ++l) {
      const long n = leaf_cells(l, nullptr);
      fits = fits && n >= 0;
      first[size_t(l) + 1] = std::max(n, 0L);
    }
    for (int l = 0; l < leaves; ++l) first[size_t(l) + 1] += first[size_t(l)];
    if (!fits || double(first.back()) > kGridEntries * leaves) continue;
    std::vector<uint64_t> pairs(size_t(first.back())), spare(pairs.size());
#pragma omp parallel for schedule(static) if (leaves > 20000)
    for (int l = 0; l < leaves; ++l) leaf_cells(l, pairs.data() + first[size_t(l)]);
    // Sorted by cell, then leaf (least significant digit first, 16 bits a pass).
    int bits = leaf_bits;
    while (bits < 64 && (uint64_t(1) << (bits - leaf_bits)) < uint64_t(dim[0] * dim[1] * dim[2])) ++bits;
    for (int shift = 0; shift < bits; shift += 16) {
      std::vector<size_t> start(65537, 0);
      for (const uint64_t k : pairs) ++start[size_t((k >> shift) & 0xffff) + 1];
      for (size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
      for (const uint64_t k : pairs) spare[start[size_t((k >> shift) & 0xffff)]++] = k;
      pairs.swap(spare);
    }
    size_t distinct = 0;
    for (size_t k = 0; k < pairs.size(); ++k) distinct += k == 0 || (pairs[k] >> leaf_bits) != (pairs[k - 1] >> leaf_bits);
    size_t size = 1024;
    while (size < 2 * distinct) size *= 2;
    cells.assign(size, Cell{});
    cell_leaf.resize(pairs.size());
    const uint64_t leaf_mask = (uint64_t(1) << leaf_bits) - 1;
    for (size_t k = 0; k < pairs.size();) {
      const uint64_t dense = pairs[k] >> leaf_bits;
      size_t e = k;
      for (; e < pairs.size() && (pairs[e] >> leaf_bits) == dense; ++e) cell_leaf[e] = int(pairs[e] & leaf_mask);
      const uint64_t i = dense / uint64_t(dim[1] * dim[2]), j = dense / uint64_t(dim[2]) % uint64_t(dim[1]), m = dense % uint64_t(dim[2]);
      const uint64_t key = i << 42 | j << 21 | m;
      size_t at = cell_hash(key) & (size - 1);
      while (cells[at].key != kNoCell) at = (at + 1) & (size - 1);
      cells[at] = {key, uint32_t(k), uint32_t(e)};
      k = e;
    }
    grid_lo = origin, grid_h = h, grid_reach = reach_now;
    return;
  }
}

// The local certificates of search(): near leaves from the corner-sharing faces, and each leaf's
// reach by an exact search from its centre that leaves its near leaves out.
void SurfaceIndex::Impl::build_certificates() {
  const int nf = int(mesh.faces.size()), nv = int(mesh.vertices.size());
  const int leaves = int(bounds.size());
  // Faces around each vertex (CSR) and each face's leaf.
  std::vector<int> vf_begin(size_t(nv) + 1, 0), vf(size_t(3) * size_t(nf)), leaf_of(size_t(nf), 0);
  for (const auto& F : mesh.faces)
    for (int v : F) ++vf_begin[size_t(v) + 1];
  for (int v = 0; v < nv; ++v) vf_begin[size_t(v) + 1] += vf_begin[size_t(v)];
  {
    std::vector<int> fill(vf_begin.begin(), vf_begin.end() - 1);
    for (int f = 0; f < nf; ++f)
      for (int v : mesh.faces[size_t(f)]) vf[size_t(fill[size_t(v)]++)] = f;
  }
  for (int k = 0; k < int(tri.size()); ++k)
    if (k < nf) leaf_of[size_t(tri[size_t(k)].face)] = k / kLeafFaces;
  const auto near_of = [&](int l, std::vector<int>& out) {
    out.clear();
    for (int k = l * kLeafFaces; k < std::min(nf, (l + 1) * kLeafFaces); ++k)
      for (int v : mesh.faces[size_t(tri[size_t(k)].face)])
        for (int j = vf_begin[size_t(v)]; j < vf_begin[size_t(v) + 1]; ++j) out.push_back(leaf_of[size_t(vf[size_t(j)])]);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  };
  near_begin.assign(size_t(leaves) + 1, 0);
#pragma omp parallel if (leaves > 2000)
  {
    std::vector<int> scratch;
#pragma omp for schedule(static)
    for (int l = 0; l < leaves; ++l) {
      near_of(l, scratch);
      near_begin[size_t(l) + 1] = int(scratch.size());
    }
  }
  for (int l = 0; l < leaves; ++l) near_begin[size_t(l) + 1] += near_begin[size_t(l)];
  near_leaf.resize(size_t(near_begin.back()));
  reach.assign(size_t(leaves), 0);
  centre.assign(size_t(leaves), Eigen::Vector3d::Zero());
#pragma omp parallel if (leaves > 2000)
  {
    std::vector<int> scratch;
#pragma omp for schedule(static)
    for (int l = 0; l < leaves; ++l) {
      near_of(l, scratch);
      std::copy(scratch.begin(), scratch.end(), near_leaf.begin() + near_begin[size_t(l)]);
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      int corners = 0;
      for (int k = l * kLeafFaces; k < std::min(nf, (l + 1) * kLeafFaces); ++k, corners += 3)
        c += tri[size_t(k)].a + tri[size_t(k)].b + tri[size_t(k)].c;
      centre[size_t(l)] = c / double(corners);
    }
  }
#pragma omp parallel for schedule(dynamic, 256) if (leaves > 200)
  for (int l = 0; l < leaves; ++l) {
    const int* const b = near_leaf.data() + near_begin[size_t(l)];
    const int* const e = near_leaf.data() + near_begin[size_t(l) + 1];
    const Eigen::Vector3d& c = centre[size_t(l)];
    // Start from the nearest leaf one ring further out (a tight first bound: the search then
    // visits little more than the boxes around c).
    int start = -1;
    double start_d2 = std::numeric_limits<double>::infinity();
    for (const int* m = b; m != e; ++m)
      for (int j = near_begin[size_t(*m)]; j < near_begin[size_t(*m) + 1]; ++j) {
        const int o = near_leaf[size_t(j)];
        const double d2 = (centre[size_t(o)] - c).squaredNorm();
        if (d2 < start_d2 && !std::binary_search(b, e, o)) start = o, start_d2 = d2;
      }
    // The nearest face outside the near leaves, exactly (the search is exact on the faces it is given).
    const Hit h = search(c, start < 0 ? -1 : start * kLeafFaces, b, e);
    reach[size_t(l)] = h.slot < 0 ? std::numeric_limits<double>::infinity() : (h.tp.point - c).norm() - 2 * slack;
  }
}

// Ordered depth-first search: the nearer children first, a child is skipped when its box is
// farther than the best face so far. Among faces at the same distance the lowest index wins, as in
// closest_brute_force, so the answer is the same face whatever the tree's shape or the order in
// which faces are met. `hint_leaf` (the first slot of a leaf, e.g. the previous query's answer in a
// batch) is tested first: a near face found early prunes most of the tree, and the answer does not
// depend on it.
//
// The boxes are bounded in float: the local coordinates R p - m are off by at most a few float
// ulps of |p|_1 + |m| (R's entries are below 1 + 1e-7), so |local| - e is lowered by kFloatError
// (|p|_1 + |m|) (the |m| part is in e since build) and the squared bound compared with a prune
// radius raised by kFloatError: a box is never pruned when the double bound would keep it.
SurfaceIndex::Impl::Hit SurfaceIndex::Impl::search(const Eigen::Vector3d& p, int hint_leaf, const int* excluded_begin,
                                                   const int* excluded_end) const {
  struct Entry {
    int link;
    float d2;
  };
  Entry stack[256];
  int top = 0;
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1;
  Hit hit;
  // A box is pruned only when it is farther than the best face by more than the rounding slack.
  const auto bound = [&](double b2) {
    const double b = std::sqrt(b2) + slack;
    const double r2 = b * b * (1 + 1e-12) * (1 + kFrameError) * (1 + kFloatError);
    // float(r2) may round down by half an ulp (2^-24 relative): raised by 2^-22.
    return r2 < 1e38 ? float(r2) * (1.0F + 0x1p-22F) : INFINITY;
  };
  float prune2 = INFINITY;
  const float x = float(p.x()), y = float(p.y()), z = float(p.z());
  const float margin = float(kFloatError * (std::abs(p.x()) + std::abs(p.y()) + std::abs(p.z())));
  // The leaf bounds subtract n.a and u.corner (|.| <= 2 coordinate_bound) instead of a centre.
  const float leaf_margin = float(kFloatError * (std::abs(p.x()) + std::abs(p.y()) + std::abs(p.z()) + 2 * coordinate_bound));
  const Node4* W = wide.data();
  const int nf = int(mesh.faces.size());
  const auto leaf_count = [&](int leaf) { return std::min(kLeafFaces, nf - leaf * kLeafFaces); };
  // The faces of a leaf in the order of their float lower bounds, each tested exactly unless its
  // bound is beyond the best face so far.
  const auto visit_leaf = [&](int first, int count) {
    alignas(16) float lb[4];
    leaf_bound4(bounds[size_t(first / kLeafFaces)], x, y, z, leaf_margin, lb);
    // The lanes still in question (bit j: face j's bound is within the prune radius), nearest
    // bound first; most leaves visited near the answer have none or one.
    const int lanes = (1 << count) - 1;
    const auto open = [&] {
#ifdef __SSE2__
      return _mm_movemask_ps(_mm_cmple_ps(_mm_mul_ps(_mm_load_ps(lb), _mm_set1_ps(float(1 - 4 * kFloatError))),
                                          _mm_set1_ps(prune2))) & lanes;
#else
      int mask = 0;
      for (int j = 0; j < count; ++j) mask |= (lb[j] * float(1 - 4 * kFloatError) <= prune2) << j;
      return mask;
#endif
    };
    for (int mask = open(); mask != 0; mask = open()) {
      int j = __builtin_ctz(unsigned(mask));
      for (int i = j + 1; i < count; ++i)
        if ((mask >> i & 1) && lb[i] < lb[j]) j = i;
      lb[j] = INFINITY;  // tested
      const int k = first + j;
      const LeafFace& T = tri[size_t(k)];
      const TrianglePoint tp = closest_on_triangle(p, T.a, T.b, T.c);
      if (closer((tp.point - p).squaredNorm(), T.face, best2, face)) {
        hit = {k, tp};
        prune2 = bound(best2);
      }
    }
  };
  // Every child that may be visited is fetched while its siblings are bounded: on big meshes the
  // search waits on memory, not arithmetic.
  const auto prefetch = [&](int child) {
    const auto lines = [](const void* a, size_t bytes) {
      for (size_t b = 0; b < bytes; b += 64) __builtin_prefetch(static_cast<const char*>(a) + b);
    };
    if (child >= 0) return lines(W + child, sizeof(Node4));
    const int first = (~child) >> 3;
    lines(&bounds[size_t(first / kLeafFaces)], sizeof(LeafBound));
    lines(&tri[size_t(first)], sizeof(LeafFace) * size_t((~child) & 7));
  };
  const bool big = prefetching;
  // The cell grid: every face within grid_reach of p is in a leaf p's cell lists.
  // A batch query whose previous answer's leaf has no face plane within twice the reach is taken
  // to be off the surface (as its predecessor was): it goes straight to the tree.
  const auto near_planes = [&] {
    if (hint_leaf < 0) return true;
    const LeafBound& lb = bounds[size_t(hint_leaf / kLeafFaces)];
    float nearest = INFINITY;
    for (int j = 0; j < leaf_count(hint_leaf / kLeafFaces); ++j)
      nearest = std::min(nearest, std::abs(lb.n[0][j] * x + lb.n[1][j] * y + lb.n[2][j] * z - lb.d[j]));
    return nearest <= float(2 * grid_reach);
  };
  if (excluded_begin == excluded_end && !cells.empty() && near_planes()) {
    if (const Cell* c = cell_of(p)) {
      const int* const b = cell_leaf.data() + c->begin;
      const int* const e = cell_leaf.data() + c->end;
      prune2 = bound(grid_reach * grid_reach);
      const int listed = int(e - b);
      if (listed <= 32) {
        // The float bounds of all listed faces first, then the faces tested in the order of their
        // bounds: the one holding p comes first and its distance prunes the rest.
        alignas(16) float lb[4 * 32];
        for (int i = 0; i < listed; ++i) {
          leaf_bound4(bounds[size_t(b[i])], x, y, z, leaf_margin, lb + 4 * i);
          for (int j = leaf_count(b[i]); j < kLeafFaces; ++j) lb[4 * i + j] = INFINITY;
        }
        for (;;) {
          int at = 0;
          for (int k = 1; k < 4 * listed; ++k)
            if (lb[k] < lb[at]) at = k;
          if (!(lb[at] * float(1 - 4 * kFloatError) <= prune2)) break;
          lb[at] = INFINITY;  // tested
          const int k = b[at / 4] * kLeafFaces + at % 4;
          const LeafFace& T = tri[size_t(k)];
          const TrianglePoint tp = closest_on_triangle(p, T.a, T.b, T.c);
          if (closer((tp.point - p).squaredNorm(), T.face, best2, face)) {
            hit = {k, tp};
            prune2 = bound(best2);
          }
        }
      } else {
        for (const int* l = b; l != e; ++l) visit_leaf(*l * kLeafFaces, leaf_count(*l));
      }
      if (face >= 0 && std::sqrt(best2) + 2 * slack < grid_reach) return hit;
      if (face < 0) prune2 = INFINITY;
    }
  }
  int hint_link = 0;  // 0 is the root, never a leaf link
  if (hint_leaf >= 0) {
    const int count = leaf_count(hint_leaf / kLeafFaces);
    hint_link = ~(hint_leaf * 8 + count);
    visit_leaf(hint_leaf, count);
    // Local certificate: every face outside the leaves near leaf l is at least reach[l] - |p - centre[l]|
    // from p (triangle inequality). When the best face so far is nearer than that by 2 slack (which
    // covers the rounding of both distances), visiting the near leaves finds the answer, and nothing
    // else can equal it, so the tie rule holds too. Tried from the hint's leaf, then once from the
    // leaf of the best face among its near leaves; on or next to the surface one of them usually
    // holds. Otherwise the tree search below runs with the best face found so far, the near leaves
    // of the hint left out (they have been visited).
    if (!near_begin.empty()) {
      const auto room = [&](int l) {
        return reach[size_t(l)] - (p - centre[size_t(l)]).norm() - 2 * slack;
      };
      const int l0 = hint_leaf / kLeafFaces;
      const double room0 = room(l0);
      if (face >= 0 && std::sqrt(best2) < reach[size_t(l0)]) {  // p is near l0: its near leaves are worth a visit
        const int* const b0 = near_leaf.data() + near_begin[size_t(l0)];
        const int* const e0 = near_leaf.data() + near_begin[size_t(l0) + 1];
        for (const int* l = b0; l != e0; ++l)
          if (*l != l0) visit_leaf(*l * kLeafFaces, leaf_count(*l));
        if (std::sqrt(best2) < room0) return hit;
        const int l1 = hit.slot / kLeafFaces;
        if (l1 != l0) {
          const double room1 = room(l1);
          if (std::sqrt(best2) < room1) {
            for (const int* l = near_leaf.data() + near_begin[size_t(l1)]; l != near_leaf.data() + near_begin[size_t(l1) + 1]; ++l)
              if (!std::binary_search(b0, e0, *l)) visit_leaf(*l * kLeafFaces, leaf_count(*l));
            if (std::sqrt(best2) < room1) return hit;  // (best2 only falls)
          }
        }
        excluded_begin = b0, excluded_end = e0;
      }
    }
  }
  stack[top++] = {0, 0.0F};
  while (top > 0) {
    const Entry en = stack[--top];
    if (en.d2 > prune2) continue;
    int link = en.link;
    for (;;) {
      if (link < 0) {
        if (link != hint_link &&
            (excluded_begin == excluded_end || !std::binary_search(excluded_begin, excluded_end, ((~link) >> 3) / kLeafFaces)))
          visit_leaf((~link) >> 3, (~link) & 7);
        break;
      }
      const Node4& w = W[link];
      alignas(16) float d2[4], key[4];
      bound4(w, x, y, z, margin, d2, key);
      // The children to visit (bit j: child j), nearest first (insertion sort of at most four).
      const int visit = near_mask(w, d2, prune2);
      if (visit == 0) break;
      if ((visit & (visit - 1)) == 0) {  // one child: no sorting, no stack
        link = w.link[__builtin_ctz(unsigned(visit))];
        if (big) prefetch(link);
        continue;
      }
      int order[4], n = 0;
      for (int j = 0; j < 4; ++j) {
        if (!(visit >> j & 1)) continue;
        int i = n++;
        for (; i > 0 && key[j] < key[order[i - 1]]; --i) order[i] = order[i - 1];
        order[i] = j;
      }
      for (int i = n - 1; i >= 0; --i) {
        const int child = w.link[order[i]];
        if (big) prefetch(child);
        if (i > 0) stack[top++] = {child, d2[order[i]]};
      }
      link = w.link[order[0]];
    }
  }
  return hit;
}

SurfaceIndex::SurfaceIndex(TriMesh mesh) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.mesh = std::move(mesh);
  s.normals = vertex_normals(s.mesh);
  s.topology = mesh_topology(s.mesh);
  const long nf = long(s.mesh.faces.size());
  double cover = 0;
#pragma omp parallel for schedule(static) reduction(max : cover) if (nf > 20000)
  for (long f = 0; f < nf; ++f) {
    const auto& F = s.mesh.faces[size_t(f)];
    cover = std::max(cover, covering_radius_of(s.mesh.vertices[size_t(F[0])], s.mesh.vertices[size_t(F[1])],
                                               s.mesh.vertices[size_t(F[2])]));
  }
  s.cover = cover;
  s.box = bounding_box(s.mesh.vertices);
  if (!s.mesh.faces.empty()) {
    s.build();
    // On big meshes a batch's neighbouring queries are rarely in one leaf's neighbourhood, and the
    // certificates' build (one search per leaf) costs more than they save (measured at 200k vertices).
    if (s.bounds.size() <= kCertificateLeaves) s.build_certificates();
    s.build_grid();
  }
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

Footpoint SurfaceIndex::closest(const Eigen::Vector3d& p) const {
  int hint = -1;
  return closest_from(p, hint);
}

Footpoint SurfaceIndex::closest_from(const Eigen::Vector3d& p, int& hint_leaf) const {
  if (!p.allFinite()) return no_footpoint();
  // Beyond 1e30 the float box bounds would overflow: such a query is answered by brute force.
  if (p.cwiseAbs().maxCoeff() > 1e30) return closest_brute_force(p);
  const Impl::Hit h = impl_->search(p, hint_leaf);
  if (h.slot >= 0) hint_leaf = h.slot - h.slot % kLeafFaces;
  return impl_->footpoint(p, h);
}

namespace {
// Spreads the low 10 bits of x to every third bit (Morton code).
uint32_t spread3(uint32_t x) {
  x &= 0x3ff;
  x = (x | x << 16) & 0x30000ff;
  x = (x | x << 8) & 0x300f00f;
  x = (x | x << 4) & 0x30c30c3;
  x = (x | x << 2) & 0x9249249;
  return x;
}
}  // namespace

std::vector<Footpoint> SurfaceIndex::closest(const std::vector<Eigen::Vector3d>& points) const {
  const long n = long(points.size());
  std::vector<Footpoint> out(points.size());
  // Queries are answered in Morton order of their position in the mesh's bounding box (30 bits:
  // 1024 cells per axis), so that neighbouring queries on one thread walk the same nodes while they
  // are in cache and each starts from the leaf of the one before. Each answer is independent of
  // the order and of the start, so out[i] is the same footpoint as closest(points[i]).
  // Keys: code << 32 | index, sorted by three passes of a 10-bit radix sort on the code.
  std::vector<uint64_t> key(static_cast<size_t>(n)), spare(static_cast<size_t>(n));
  const Eigen::Vector3d lo = impl_->box.min, size = (impl_->box.max - impl_->box.min).cwiseMax(1e-300);
  const bool sort = n > 1024 && n < (1L << 32);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (long i = 0; i < n; ++i) {
    uint64_t code = 0;
    if (sort && points[size_t(i)].allFinite())
      for (int k = 0; k < 3; ++k) {
        const double f = std::clamp((points[size_t(i)][k] - lo[k]) / size[k], 0.0, 1.0);
        code |= uint64_t(spread3(uint32_t(f * 1023.0))) << k;
      }
    key[size_t(i)] = code << 32 | uint64_t(i);
  }
  if (sort)
    for (int shift = 32; shift < 62; shift += 10) {
      std::array<size_t, 1025> start{};
      for (const uint64_t k : key) ++start[size_t((k >> shift) & 1023) + 1];
      for (size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
      for (const uint64_t k : key) spare[start[size_t((k >> shift) & 1023)]++] = k;
      key.swap(spare);
    }
  const auto index = [&](long j) { return sort ? long(key[size_t(j)] & 0xffffffffULL) : j; };
#pragma omp parallel if (n > 256)
  {
    int hint = -1;  // this thread's last answer: the next query in Morton order is usually near it
#pragma omp for schedule(static)
    for (long j = 0; j < n; ++j) {
      // The point and the answer of a query a few ahead are fetched while this one is searched.
      if (j + 32 < n) {
        const long ahead = index(j + 32);
        __builtin_prefetch(&points[size_t(ahead)]);
        __builtin_prefetch(&out[size_t(ahead)], 1);
        __builtin_prefetch(reinterpret_cast<const char*>(&out[size_t(ahead)]) + sizeof(Footpoint) - 1, 1);
      }
      if (impl_->prefetching && j + 16 < n) impl_->prefetch_slot(points[size_t(index(j + 16))]);
      if (impl_->prefetching && j + 8 < n) impl_->prefetch_cell(points[size_t(index(j + 8))]);
      const long i = index(j);
      out[size_t(i)] = closest_from(points[size_t(i)], hint);
    }
  }
  return out;
}

Footpoint SurfaceIndex::closest_brute_force(const Eigen::Vector3d& p) const {
  if (!p.allFinite()) return no_footpoint();
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1;
  for (int f = 0; f < int(impl_->mesh.faces.size()); ++f)
    closer(impl_->face_distance2(f, p), f, best2, face);
  if (face < 0) return no_footpoint();
  const Impl& s = *impl_;
  const auto& F = s.mesh.faces[size_t(face)];
  const TrianglePoint tp = closest_on_triangle(p, s.mesh.vertices[size_t(F[0])], s.mesh.vertices[size_t(F[1])], s.mesh.vertices[size_t(F[2])]);
  return s.make_footpoint(p, face, tp, s.boundary_flags(face));
}

namespace {
// The closest point to p of the triangle (a, b, c) clipped to the slab lo <= <x, n> <= hi
// (Sutherland-Hodgman against both planes, then the nearest of the clipped polygon's fan); false
// when the triangle misses the slab. A triangle inside the slab is answered as closest() answers it.
bool closest_on_clipped(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& n, double lo, double hi, Eigen::Vector3d& out) {
  const double ha = n.dot(a), hb = n.dot(b), hc = n.dot(c);
  if (std::max({ha, hb, hc}) < lo || std::min({ha, hb, hc}) > hi) return false;
  if (std::min({ha, hb, hc}) >= lo && std::max({ha, hb, hc}) <= hi) {
    out = closest_on_triangle(p, a, b, c).point;
    return true;
  }
  std::array<Eigen::Vector3d, 5> poly{a, b, c}, next;
  int count = 3;
  for (const double sign : {1.0, -1.0}) {  // keep sign * (<x, n> - level) >= 0
    const double level = sign > 0 ? lo : hi;
    int kept = 0;
    for (int i = 0; i < count; ++i) {
      const Eigen::Vector3d& u = poly[size_t(i)];
      const Eigen::Vector3d& v = poly[size_t((i + 1) % count)];
      const double du = sign * (n.dot(u) - level), dv = sign * (n.dot(v) - level);
      if (du >= 0) next[size_t(kept++)] = u;
      if ((du >= 0) != (dv >= 0) && du != dv) next[size_t(kept++)] = u + (du / (du - dv)) * (v - u);
    }
    poly = next;
    count = kept;
    if (count == 0) return false;
  }
  if (count < 3) {
    out = closest_on_triangle(p, poly[0], poly[size_t(count - 1)], poly[size_t(count - 1)]).point;
    return true;
  }
  double best = std::numeric_limits<double>::infinity();
  for (int i = 1; i + 1 < count; ++i) {
    const Eigen::Vector3d q = closest_on_triangle(p, poly[0], poly[size_t(i)], poly[size_t(i + 1)]).point;
    const double d2 = (q - p).squaredNorm();
    if (d2 < best) best = d2, out = q;
  }
  return true;
}

// Barycentric coordinates of x (in the plane of the face, or projected onto it) in (a, b, c).
Eigen::Vector3d barycentric_of(const Eigen::Vector3d& x, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const Eigen::Vector3d& c) {
  const Eigen::Vector3d v0 = b - a, v1 = c - a, v2 = x - a;
  const double d00 = v0.dot(v0), d01 = v0.dot(v1), d11 = v1.dot(v1), d20 = v2.dot(v0), d21 = v2.dot(v1);
  const double den = d00 * d11 - d01 * d01;
  if (!(std::abs(den) > 1e-300)) return {1, 0, 0};
  const double v = (d11 * d20 - d01 * d21) / den, w = (d00 * d21 - d01 * d20) / den;
  return {1 - v - w, v, w};
}
}  // namespace

Footpoint SurfaceIndex::closest_in_slab(const Eigen::Vector3d& p, const Eigen::Vector3d& direction, double lo,
                                        double hi) const {
  if (!p.allFinite() || !direction.allFinite() || !(lo <= hi) || p.cwiseAbs().maxCoeff() > 1e30)
    return closest_in_slab_brute_force(p, direction, lo, hi);
  const Impl& s = *impl_;
  const Eigen::Vector3d n = direction.normalized();
  const int nf = int(s.mesh.faces.size());
  if (nf == 0) return no_footpoint();
  const float x = float(p.x()), y = float(p.y()), z = float(p.z());
  const float margin = float(kFloatError * (std::abs(p.x()) + std::abs(p.y()) + std::abs(p.z())));
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1, slot = -1;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  float prune2 = INFINITY;
  const auto bound = [&](double b2) {  // as in Impl::search: pruned only beyond the rounding slack
    const double b = std::sqrt(b2) + s.slack;
    const double r2 = b * b * (1 + 1e-12) * (1 + kFrameError) * (1 + kFloatError);
    return r2 < 1e38 ? float(r2) * (1.0F + 0x1p-22F) : INFINITY;
  };
  const auto visit_leaf = [&](int first, int count) {
    for (int j = 0; j < count; ++j) {
      const LeafFace& T = s.tri[size_t(first + j)];
      Eigen::Vector3d q;
      if (!closest_on_clipped(p, T.a, T.b, T.c, n, lo, hi, q)) continue;
      if (closer((q - p).squaredNorm(), T.face, best2, face)) {
        slot = first + j, at = q;
        prune2 = bound(best2);
      }
    }
  };
  // A child box is left out when its extent along n (the box's centre and half extents in its own
  // frame, projected; widened by the frame's rounding) misses the slab.
  const auto meets_slab = [&](const Node4& w, int j) {
    double centre = 0, half = 0, size = 0;
    for (int k = 0; k < 3; ++k) {
      const double c = n.x() * w.R[3 * k][j] + n.y() * w.R[3 * k + 1][j] + n.z() * w.R[3 * k + 2][j];
      centre += c * w.m[k][j];
      half += std::abs(c) * w.e[k][j];
      size += std::abs(w.m[k][j]) + w.e[k][j];
    }
    const double pad = 1e-5 * size + 2 * s.slack;
    return centre + half + pad >= lo && centre - half - pad <= hi;
  };
  struct Entry {
    int link;
    float d2;
  };
  // Depth first, at most three entries left behind per level of the tree (as in Impl::search).
  Entry stack[256];
  int top = 0;
  if (s.wide.empty()) visit_leaf(0, std::min(kLeafFaces, nf));
  else stack[top++] = {0, 0.0F};
  while (top > 0) {
    const Entry en = stack[--top];
    if (en.d2 > prune2) continue;
    if (en.link < 0) {
      visit_leaf((~en.link) >> 3, (~en.link) & 7);
      continue;
    }
    const Node4& w = s.wide[size_t(en.link)];
    alignas(16) float d2[4], key[4];
    bound4(w, x, y, z, margin, d2, key);
    int order[4], m = 0;
    for (int j = 0; j < 4; ++j) {
      if (w.link[j] == kEmptyLane || !(d2[j] <= prune2) || !meets_slab(w, j)) continue;
      int i = m++;
      for (; i > 0 && d2[j] < d2[order[i - 1]]; --i) order[i] = order[i - 1];
      order[i] = j;
    }
    for (int i = m - 1; i >= 0; --i) stack[top++] = {w.link[order[i]], d2[order[i]]};
  }
  if (face < 0) return no_footpoint();
  const LeafFace& T = s.tri[size_t(slot)];
  return s.make_footpoint(p, face, {at, barycentric_of(at, T.a, T.b, T.c)}, T.boundary);
}

Footpoint SurfaceIndex::closest_in_slab_brute_force(const Eigen::Vector3d& p, const Eigen::Vector3d& direction, double lo,
                                                    double hi) const {
  const Impl& s = *impl_;
  if (!p.allFinite() || !direction.allFinite() || !(lo <= hi)) return no_footpoint();
  const Eigen::Vector3d n = direction.normalized();
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  for (int f = 0; f < int(s.mesh.faces.size()); ++f) {
    const auto& F = s.mesh.faces[size_t(f)];
    Eigen::Vector3d q;
    if (!closest_on_clipped(p, s.mesh.vertices[size_t(F[0])], s.mesh.vertices[size_t(F[1])], s.mesh.vertices[size_t(F[2])], n,
                            lo, hi, q))
      continue;
    if (closer((q - p).squaredNorm(), f, best2, face)) at = q;
  }
  if (face < 0) return no_footpoint();
  const auto& F = s.mesh.faces[size_t(face)];
  const TrianglePoint tp{at, barycentric_of(at, s.mesh.vertices[size_t(F[0])], s.mesh.vertices[size_t(F[1])],
                                            s.mesh.vertices[size_t(F[2])])};
  return s.make_footpoint(p, face, tp, s.boundary_flags(face));
}

namespace {
// The face across each edge (corners k, k+1) of every face: the one other face with that edge, or -1
// (a boundary edge, or one shared by more than two faces).
std::vector<std::array<int, 3>> faces_across(const TriMesh& m) {
  struct Edge {
    uint64_t key;
    int face, edge;
  };
  std::vector<Edge> edges;
  edges.reserve(3 * m.faces.size());
  for (size_t f = 0; f < m.faces.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const auto a = uint32_t(m.faces[f][size_t(k)]), b = uint32_t(m.faces[f][size_t((k + 1) % 3)]);
      edges.push_back({uint64_t(std::min(a, b)) << 32 | std::max(a, b), int(f), k});
    }
  std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
    return x.key != y.key ? x.key < y.key : x.face != y.face ? x.face < y.face : x.edge < y.edge;
  });
  std::vector<std::array<int, 3>> across(m.faces.size(), {-1, -1, -1});
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i == 2) {
      across[size_t(edges[i].face)][size_t(edges[i].edge)] = edges[i + 1].face;
      across[size_t(edges[i + 1].face)][size_t(edges[i + 1].edge)] = edges[i].face;
    }
    i = j;
  }
  return across;
}
}  // namespace

Eigen::Vector3d SurfaceIndex::pseudo_normal(const Footpoint& f) const {
  Impl& s = *impl_;
  if (f.face < 0 || size_t(f.face) >= s.mesh.faces.size()) return Eigen::Vector3d::Zero();
  const auto& F = s.mesh.faces[size_t(f.face)];
  const Eigen::Vector3d nf = face_normal(s.mesh, f.face);
  const double eps = 1e-9;
  for (int k = 0; k < 3; ++k)  // at a corner
    if (f.barycentric[k] > 1 - eps) return s.normals[size_t(F[size_t(k)])];
  for (int k = 0; k < 3; ++k)  // on the edge opposite corner k, i.e. edge (k + 1) % 3
    if (f.barycentric[k] < eps) {
      std::call_once(s.across_once, [&s] { s.across = faces_across(s.mesh); });
      const int g = s.across[size_t(f.face)][size_t((k + 1) % 3)];
      const Eigen::Vector3d n = nf + (g >= 0 ? face_normal(s.mesh, g) : Eigen::Vector3d::Zero());
      return n.norm() > 1e-12 ? Eigen::Vector3d(n.normalized()) : nf;
    }
  return nf;
}

const TriMesh& SurfaceIndex::mesh() const { return impl_->mesh; }
const std::vector<Eigen::Vector3d>& SurfaceIndex::normals() const { return impl_->normals; }
const MeshTopology& SurfaceIndex::topology() const { return impl_->topology; }
double SurfaceIndex::covering_radius() const { return impl_->cover; }

}  // namespace flankcam
