#include "placement/fov_volume.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <unsupported/Eigen/AutoDiff>

#include "common/check.h"
#include "common/config_error.h"

namespace hg::placement {
namespace {

using Ad = Eigen::AutoDiffScalar<Eigen::Matrix<double, 6, 1>>;

inline double Val(double x) { return x; }
inline double Val(const Ad& x) { return x.value(); }

// Pieces whose image area (normalised coordinates, relative to the frustum's)
// falls below this are dropped: far below a pixel, they only cost time.
constexpr double kRelMinArea = 1e-14;
// Two planes whose inverse depths agree to this relative accuracy over a face
// are one plane (rounding of the camera transform), ordered by index.
constexpr double kCoplanarTol = 1e-10;
// A face whose plane passes this close to the camera (relative to its size)
// is seen edge-on: no area in the image, no volume.
constexpr double kEdgeOnTol = 1e-12;
// Components with more faces in view than this find their occluding faces
// through an image grid instead of a loop over their faces.
constexpr int kLargeComponent = 64;

template <typename S>
struct P2 {
  S u;
  S v;
};

template <typename S>
struct P3 {
  S x;
  S y;
  S z;
};

// A line of the image, a * u + b * v + c = 0, inside where >= 0; equally the
// plane through the camera centre a * x + b * y + c * z = 0 whose trace it is.
template <typename S>
struct Line {
  S a;
  S b;
  S c;
};

template <typename S>
inline S Eval(const Line<S>& l, const P2<S>& p) {
  return l.a * p.u + l.b * p.v + l.c;
}
template <typename S>
inline S Eval(const Line<S>& l, const P3<S>& p) {
  return l.a * p.x + l.b * p.y + l.c * p.z;
}
template <typename S>
inline P2<S> Lerp(const P2<S>& p, const P2<S>& q, const S& s) {
  return {p.u + (q.u - p.u) * s, p.v + (q.v - p.v) * s};
}
template <typename S>
inline P3<S> Lerp(const P3<S>& p, const P3<S>& q, const S& s) {
  return {p.x + (q.x - p.x) * s, p.y + (q.y - p.y) * s, p.z + (q.z - p.z) * s};
}
template <typename S>
inline Line<S> Flip(const Line<S>& l) {
  return {-l.a, -l.b, -l.c};
}

// A convex polygon and, per edge i (vertex i to i + 1), the line it lies on,
// inside >= 0. The lines come from the scene's planes (triangle edges, frustum
// sides, depth cuts) and are never recomputed from two vertices, which may be
// arbitrarily close after clipping and would tilt the line.
template <typename Pt, typename S>
struct PolyOf {
  std::vector<Pt> p;
  std::vector<Line<S>> l;
  void clear() {
    p.clear();
    l.clear();
  }
  void push(const Pt& pt, const Line<S>& line) {
    p.push_back(pt);
    l.push_back(line);
  }
  [[nodiscard]] int size() const { return static_cast<int>(p.size()); }
};
template <typename S>
using Poly2 = PolyOf<P2<S>, S>;
template <typename S>
using Poly3 = PolyOf<P3<S>, S>;

struct Bbox {
  double u0 = 0;
  double v0 = 0;
  double u1 = -1;
  double v1 = -1;
  [[nodiscard]] bool Overlaps(const Bbox& o) const {
    return u0 <= o.u1 && o.u0 <= u1 && v0 <= o.v1 && o.v0 <= v1;
  }
};

template <typename S>
Bbox BoundsOf(const P2<S>* p, int n) {
  Bbox b{Val(p[0].u), Val(p[0].v), Val(p[0].u), Val(p[0].v)};
  for (int i = 1; i < n; ++i) {
    b.u0 = std::min(b.u0, Val(p[i].u));
    b.u1 = std::max(b.u1, Val(p[i].u));
    b.v0 = std::min(b.v0, Val(p[i].v));
    b.v1 = std::max(b.v1, Val(p[i].v));
  }
  return b;
}

template <typename S>
double SignedArea(const P2<S>* p, int n) {
  double twice = 0.0;
  for (int i = 0, j = n - 1; i < n; j = i++) {
    twice += Val(p[j].u) * Val(p[i].v) - Val(p[i].u) * Val(p[j].v);
  }
  return 0.5 * twice;
}

enum class Side { kIn, kOut, kSplit };

// Splits the convex polygon (p, l)[0..n) by `cut`: the part with f >= 0 into
// `in`, the part with f <= 0 into `out` (when not null), each edge labelled
// with its line. Sides are decided on values; new vertices are interpolated in
// S so that derivatives follow them. When the polygon lies on one side
// (touching allowed) nothing is written and kIn or kOut is returned.
template <typename Pt, typename S>
Side Split(const Pt* p, const Line<S>* l, int n, const Line<S>& cut, PolyOf<Pt, S>* in,
           PolyOf<Pt, S>* out, std::vector<S>* f) {
  f->resize(n);
  bool any_pos = false;
  bool any_neg = false;
  for (int i = 0; i < n; ++i) {
    (*f)[i] = Eval(cut, p[i]);
    any_pos = any_pos || Val((*f)[i]) > 0;
    any_neg = any_neg || Val((*f)[i]) < 0;
  }
  if (!any_neg) return Side::kIn;
  if (!any_pos) return Side::kOut;
  in->clear();
  if (out != nullptr) out->clear();
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1 == n) ? 0 : i + 1;
    const double fi = Val((*f)[i]);
    const double fj = Val((*f)[j]);
    if (fi >= 0) in->push(p[i], (fi == 0 && fj < 0) ? cut : l[i]);
    if (out != nullptr && fi <= 0) out->push(p[i], (fi == 0 && fj > 0) ? Flip(cut) : l[i]);
    if (fi > 0 && fj < 0) {
      const Pt x = Lerp(p[i], p[j], S((*f)[i] / ((*f)[i] - (*f)[j])));
      in->push(x, cut);
      if (out != nullptr) out->push(x, l[i]);
    } else if (fi < 0 && fj > 0) {
      const Pt x = Lerp(p[i], p[j], S((*f)[i] / ((*f)[i] - (*f)[j])));
      in->push(x, l[i]);
      if (out != nullptr) out->push(x, Flip(cut));
    }
  }
  return Side::kSplit;
}

// Volume of the cone from the camera over the convex image polygon p (counter-
// clockwise) up to the plane with inverse depth 1/z = m . (u, v, 1).
template <typename S>
S ConeVolume(const P2<S>* p, int n, const std::array<S, 3>& m) {
  const auto depth = [&](const P2<S>& w) -> S { return S(1.0) / (m[0] * w.u + m[1] * w.v + m[2]); };
  const S t0 = depth(p[0]);
  S t_prev = depth(p[1]);
  S sum(0.0);
  for (int i = 1; i + 1 < n; ++i) {
    const S t_next = depth(p[i + 1]);
    const S twice_area =
        (p[i].u - p[0].u) * (p[i + 1].v - p[0].v) - (p[i].v - p[0].v) * (p[i + 1].u - p[0].u);
    sum += t_prev * t_next * twice_area;
    t_prev = t_next;
  }
  return t0 * sum / 6.0;
}

struct PieceRef {
  int begin = 0;
  int count = 0;  // 0: removed
  Bbox box;
};

// A set of disjoint convex polygons (counter-clockwise) with edge lines.
// Subtraction removes pieces in place and appends the fragments; the storage
// is compacted when removed pieces dominate.
template <typename S>
struct PieceSet {
  std::vector<P2<S>> pts;
  std::vector<Line<S>> lines;
  std::vector<PieceRef> pieces;
  int alive = 0;

  void Clear() {
    pts.clear();
    lines.clear();
    pieces.clear();
    alive = 0;
  }
  void Add(const P2<S>* p, const Line<S>* l, int n, const Bbox& box) {
    pieces.push_back({static_cast<int>(pts.size()), n, box});
    pts.insert(pts.end(), p, p + n);
    lines.insert(lines.end(), l, l + n);
    ++alive;
  }
  void Add(const Poly2<S>& poly) {
    Add(poly.p.data(), poly.l.data(), poly.size(), BoundsOf(poly.p.data(), poly.size()));
  }
  void Remove(int i) {
    pieces[i].count = 0;
    --alive;
  }
  void Compact() {
    int out_piece = 0;
    int out_pt = 0;
    for (const PieceRef& piece : pieces) {
      if (piece.count == 0) continue;
      std::copy(pts.begin() + piece.begin, pts.begin() + piece.begin + piece.count,
                pts.begin() + out_pt);
      std::copy(lines.begin() + piece.begin, lines.begin() + piece.begin + piece.count,
                lines.begin() + out_pt);
      pieces[out_piece++] = {out_pt, piece.count, piece.box};
      out_pt += piece.count;
    }
    pieces.resize(out_piece);
    pts.resize(out_pt);
    lines.resize(out_pt);
  }
};

// One triangle as the camera sees it: its footprint (convex, counter-clockwise,
// inside the frustum) and its plane as inverse depth over the image.
template <typename S>
struct Face {
  int begin = 0;  // footprint in Workspace::face_pts / face_lines
  int count = 0;
  std::array<S, 3> m;  // 1 / z = m . (u, v, 1)
  double zmin = 0;
  double zmax = 0;
  Bbox box;
  int component = -1;  // obstacles: global component; cell: -1
  int id = 0;          // order among coplanar faces
  int sign = 1;        // cell: +1 where rays leave the cell, -1 where they enter
};

template <typename S>
struct Workspace {
  std::vector<P3<S>> cell_pts;
  std::vector<P3<S>> obstacle_pts;
  std::vector<P3<S>> object_pts;
  std::vector<P2<S>> face_pts;
  std::vector<Line<S>> face_lines;
  std::vector<Face<S>> cell_faces;
  std::vector<Face<S>> faces;
  Poly3<S> clip_a;
  Poly3<S> clip_b;
  std::vector<S> f;
  Poly2<S> poly_a;
  Poly2<S> poly_b;
  Poly2<S> poly_c;
  Poly2<S> occluder;
  PieceSet<S> seen;
  // Image grid over the obstacle faces: faces of cell c are
  // grid_items[grid_start[c] .. grid_start[c + 1]).
  std::vector<int> grid_start;
  std::vector<int> grid_items;
  std::vector<int> stamp;
  std::vector<int> candidates;
  std::vector<int> cell_candidates;
  // Per global obstacle component: which faces count (+1 those facing the
  // camera, -1 those facing away, 0 both) and whether they never hide each other.
  std::vector<int> keep;
  std::vector<char> convex;
  // Per global component: its faces ws->faces[first_face, end_face), their
  // image bounds and nearest depth.
  std::vector<int> first_face;
  std::vector<int> end_face;
  std::vector<Bbox> comp_box;
  std::vector<double> comp_zmin;
};

// Frustum of the intrinsics in the camera frame: the four inward side-plane
// normals and the image corners in normalised coordinates.
struct Frustum {
  std::array<Eigen::Vector3d, 4> normals;
  Bbox box;
  double min_area = 0;
};

Frustum MakeFrustum(const Intrinsics& in) {
  HG_CHECK(in.width > 0 && in.height > 0);
  const Eigen::Matrix3d K_inv = in.K.inverse();
  const double w = in.width - 0.5;
  const double h = in.height - 0.5;
  const std::array<Eigen::Vector3d, 4> px = {Eigen::Vector3d(-0.5, -0.5, 1),
                                             Eigen::Vector3d(w, -0.5, 1), Eigen::Vector3d(w, h, 1),
                                             Eigen::Vector3d(-0.5, h, 1)};
  std::array<Eigen::Vector3d, 4> c;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int i = 0; i < 4; ++i) {
    c[i] = K_inv * px[i];
    c[i] /= c[i].z();
    centre += c[i];
  }
  Frustum fr;
  fr.box = {c[0].x(), c[0].y(), c[0].x(), c[0].y()};
  for (int i = 0; i < 4; ++i) {
    Eigen::Vector3d n = c[i].cross(c[(i + 1) % 4]);
    if (n.dot(centre) < 0) n = -n;
    fr.normals[i] = n.normalized();
    fr.box.u0 = std::min(fr.box.u0, c[i].x());
    fr.box.u1 = std::max(fr.box.u1, c[i].x());
    fr.box.v0 = std::min(fr.box.v0, c[i].y());
    fr.box.v1 = std::max(fr.box.v1, c[i].y());
  }
  const Eigen::Vector3d d02 = c[2] - c[0];
  const Eigen::Vector3d d13 = c[3] - c[1];
  fr.min_area = kRelMinArea * 0.5 * std::abs(d02.x() * d13.y() - d02.y() * d13.x());
  return fr;
}

// Camera-frame coordinates of world points. The double version is the plain
// transform; the AutoDiff version seeds d/d position (0..2) and d/d delta
// (3..5) with R_CW(delta) = Exp(-delta) R_CW, to first order p - delta x p.
void ToCamera(const std::vector<Eigen::Vector3d>& p_W, const CameraPose& pose,
              std::vector<P3<double>>* out) {
  const Eigen::Matrix3d R_CW = pose.R_WC.transpose();
  out->resize(p_W.size());
  for (size_t i = 0; i < p_W.size(); ++i) {
    const Eigen::Vector3d q = R_CW * (p_W[i] - pose.position_W);
    (*out)[i] = {q.x(), q.y(), q.z()};
  }
}

void ToCamera(const std::vector<Eigen::Vector3d>& p_W, const CameraPose& pose,
              std::vector<P3<Ad>>* out) {
  const Eigen::Matrix3d R_CW = pose.R_WC.transpose();
  out->resize(p_W.size());
  using Der = Ad::DerType;
  for (size_t i = 0; i < p_W.size(); ++i) {
    const Eigen::Vector3d q = R_CW * (p_W[i] - pose.position_W);
    // dq/dc = -R_CW; dq/ddelta = [q]x (from -delta x q = q x delta).
    std::array<Der, 3> d;
    for (int r = 0; r < 3; ++r) d[r].head<3>() = -R_CW.row(r).transpose();
    d[0].tail<3>() = Eigen::Vector3d(0, -q.z(), q.y());
    d[1].tail<3>() = Eigen::Vector3d(q.z(), 0, -q.x());
    d[2].tail<3>() = Eigen::Vector3d(-q.y(), q.x(), 0);
    (*out)[i] = {Ad(q.x(), d[0]), Ad(q.y(), d[1]), Ad(q.z(), d[2])};
  }
}

// The plane through the camera centre and the edge a-b, inside towards c.
template <typename S>
Line<S> EdgePlane(const P3<S>& a, const P3<S>& b, const P3<S>& c) {
  const Line<S> n{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  return Val(Eval(n, c)) < 0 ? Flip(n) : n;
}

// Clips a triangle (camera frame) by the frustum and projects it. Returns false
// when nothing of it is inside or it is seen edge-on; otherwise fills the
// footprint (appended to ws->face_pts / face_lines), the plane and the ranges.
// `d_sign` receives the sign of n . p for the triangle's normal n (negative: the
// triangle faces the camera). `keep`: +1 only faces with n . p < 0, -1 only
// those with n . p > 0, 0 both.
template <typename S>
bool PrepareFace(const P3<S>& p0, const P3<S>& p1, const P3<S>& p2, const Frustum& fr, int keep,
                 Workspace<S>* ws, Face<S>* face, int* d_sign) {
  const S e1x = p1.x - p0.x, e1y = p1.y - p0.y, e1z = p1.z - p0.z;
  const S e2x = p2.x - p0.x, e2y = p2.y - p0.y, e2z = p2.z - p0.z;
  const S nx = e1y * e2z - e1z * e2y;
  const S ny = e1z * e2x - e1x * e2z;
  const S nz = e1x * e2y - e1y * e2x;
  const S d = nx * p0.x + ny * p0.y + nz * p0.z;
  const double dv = Val(d);
  if ((keep > 0 && dv >= 0) || (keep < 0 && dv <= 0)) return false;
  const double n_len = std::sqrt(Val(nx) * Val(nx) + Val(ny) * Val(ny) + Val(nz) * Val(nz));
  const double reach = std::max({std::abs(Val(p0.x)), std::abs(Val(p0.y)), std::abs(Val(p0.z)),
                                 std::abs(Val(p1.x)), std::abs(Val(p1.y)), std::abs(Val(p1.z)),
                                 std::abs(Val(p2.x)), std::abs(Val(p2.y)), std::abs(Val(p2.z))});
  if (!(std::abs(dv) > kEdgeOnTol * n_len * reach)) return false;
  // Quick reject: all three corners outside one frustum plane.
  for (const Eigen::Vector3d& n : fr.normals) {
    const auto side = [&](const P3<S>& p) {
      return n.x() * Val(p.x) + n.y() * Val(p.y) + n.z() * Val(p.z);
    };
    if (side(p0) < 0 && side(p1) < 0 && side(p2) < 0) return false;
  }
  Poly3<S>* a = &ws->clip_a;
  Poly3<S>* b = &ws->clip_b;
  a->clear();
  a->push(p0, EdgePlane(p0, p1, p2));
  a->push(p1, EdgePlane(p1, p2, p0));
  a->push(p2, EdgePlane(p2, p0, p1));
  for (const Eigen::Vector3d& n : fr.normals) {
    const Line<S> cut{S(n.x()), S(n.y()), S(n.z())};
    const Side side =
        Split(a->p.data(), a->l.data(), a->size(), cut, b, static_cast<Poly3<S>*>(nullptr), &ws->f);
    if (side == Side::kIn) continue;
    if (side == Side::kOut) return false;
    std::swap(a, b);
    if (a->size() < 3) return false;
  }
  const int begin = static_cast<int>(ws->face_pts.size());
  const int count = a->size();
  face->zmin = std::numeric_limits<double>::infinity();
  face->zmax = 0;
  for (const P3<S>& p : a->p) {
    // Inside the four side planes every point but the camera centre has z > 0,
    // and the plane does not pass through the centre. A plane through the
    // centre is its own trace in the image: the edge lines carry over.
    ws->face_pts.push_back({p.x / p.z, p.y / p.z});
    face->zmin = std::min(face->zmin, Val(p.z));
    face->zmax = std::max(face->zmax, Val(p.z));
  }
  ws->face_lines.insert(ws->face_lines.end(), a->l.begin(), a->l.end());
  P2<S>* poly = ws->face_pts.data() + begin;
  const double area = SignedArea(poly, count);
  if (std::abs(area) <= fr.min_area) {
    ws->face_pts.resize(begin);
    ws->face_lines.resize(begin);
    return false;
  }
  if (area < 0) {
    // Reversed vertices: edge i runs along what was edge n - 2 - i.
    std::reverse(poly, poly + count);
    Line<S>* lines = ws->face_lines.data() + begin;
    std::reverse(lines, lines + count);
    std::rotate(lines, lines + 1, lines + count);
  }
  face->begin = begin;
  face->count = count;
  face->m = {nx / d, ny / d, nz / d};
  face->box = BoundsOf(poly, count);
  *d_sign = dv > 0 ? 1 : -1;
  return true;
}

// How `other` relates in depth to `face` over face's footprint, from the sign
// of (m_other - m_face) . w at face's corners (positive: other is nearer).
enum class DepthRelation { kCoplanar, kNowhereNearer, kEverywhereNearerOrEqual, kSplit };

template <typename S>
DepthRelation Relate(const Face<S>& face, const Face<S>& other, const P2<S>* face_poly,
                     Line<S>* line) {
  const Line<S> g{other.m[0] - face.m[0], other.m[1] - face.m[1], other.m[2] - face.m[2]};
  bool coplanar = true;
  bool any_pos = false;
  bool any_neg = false;
  for (int i = 0; i < face.count; ++i) {
    const double u = Val(face_poly[i].u);
    const double v = Val(face_poly[i].v);
    const double gv = Val(g.a) * u + Val(g.b) * v + Val(g.c);
    const double fv = Val(face.m[0]) * u + Val(face.m[1]) * v + Val(face.m[2]);
    if (std::abs(gv) > kCoplanarTol * std::abs(fv)) {
      coplanar = false;
      any_pos = any_pos || gv > 0;
      any_neg = any_neg || gv < 0;
    }
  }
  if (coplanar) return DepthRelation::kCoplanar;
  if (!any_pos) return DepthRelation::kNowhereNearer;
  if (!any_neg) return DepthRelation::kEverywhereNearerOrEqual;
  *line = g;
  return DepthRelation::kSplit;
}

// Removes the convex polygon ws->occluder from `set`.
template <typename S>
void Subtract(const Bbox& occ_box, double min_area, Workspace<S>* ws, PieceSet<S>* set) {
  const Poly2<S>& occ = ws->occluder;
  const int occ_n = occ.size();
  const int n_pieces = static_cast<int>(set->pieces.size());
  for (int k = 0; k < n_pieces; ++k) {
    const PieceRef piece = set->pieces[k];
    if (piece.count == 0 || !piece.box.Overlaps(occ_box)) continue;
    const P2<S>* p = set->pts.data() + piece.begin;
    const Line<S>* pl = set->lines.data() + piece.begin;
    // A separating line among the occluder's edges, then among the piece's.
    bool separated = false;
    for (int e = 0; !separated && e < occ_n; ++e) {
      separated = true;
      for (int i = 0; i < piece.count && separated; ++i) {
        separated = Val(Eval(occ.l[e], p[i])) <= 0;
      }
    }
    for (int e = 0; !separated && e < piece.count; ++e) {
      separated = true;
      for (int i = 0; i < occ_n && separated; ++i) {
        separated = Val(Eval(pl[e], occ.p[i])) <= 0;
      }
    }
    if (separated) continue;
    Poly2<S>* cur = &ws->poly_a;
    cur->p.assign(p, p + piece.count);
    cur->l.assign(pl, pl + piece.count);
    set->Remove(k);
    for (int e = 0; e < occ_n; ++e) {
      const Side side = Split(cur->p.data(), cur->l.data(), cur->size(), occ.l[e], &ws->poly_b,
                              &ws->poly_c, &ws->f);
      if (side == Side::kIn) continue;
      if (side == Side::kOut) {  // Not reached after the separation test, but exact.
        set->Add(*cur);
        break;
      }
      if (ws->poly_c.size() >= 3 && SignedArea(ws->poly_c.p.data(), ws->poly_c.size()) > min_area) {
        set->Add(ws->poly_c);
      }
      if (ws->poly_b.size() < 3 || SignedArea(ws->poly_b.p.data(), ws->poly_b.size()) <= min_area) {
        break;
      }
      std::swap(*cur, ws->poly_b);
    }
  }
  if (2 * set->alive < static_cast<int>(set->pieces.size())) set->Compact();
}

// Sets ws->occluder to footprint(g), cut by `line` when given.
template <typename S>
bool MakeOccluder(const Face<S>& g, const Line<S>* line, double min_area, Workspace<S>* ws) {
  const P2<S>* gp = ws->face_pts.data() + g.begin;
  const Line<S>* gl = ws->face_lines.data() + g.begin;
  if (line == nullptr) {
    ws->occluder.p.assign(gp, gp + g.count);
    ws->occluder.l.assign(gl, gl + g.count);
    return true;
  }
  const Side side =
      Split(gp, gl, g.count, *line, &ws->occluder, static_cast<Poly2<S>*>(nullptr), &ws->f);
  if (side == Side::kOut) return false;
  if (side == Side::kIn) {
    ws->occluder.p.assign(gp, gp + g.count);
    ws->occluder.l.assign(gl, gl + g.count);
    return true;
  }
  return ws->occluder.size() >= 3 &&
         SignedArea(ws->occluder.p.data(), ws->occluder.size()) > min_area;
}

// Generalised winding number of the closed triangles [first, first + count)
// around p (1 inside, 0 outside).
double WindingNumber(const geometry::TriangleMesh& mesh, int first, int count,
                     const Eigen::Vector3d& p) {
  double total = 0;
  for (int t = first; t < first + count; ++t) {
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector3d a = mesh.vertices[tri[0]] - p;
    const Eigen::Vector3d b = mesh.vertices[tri[1]] - p;
    const Eigen::Vector3d c = mesh.vertices[tri[2]] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    total += 2.0 * std::atan2(num, den);
  }
  return total / (4.0 * std::numbers::pi);
}

struct MeshAnalysis {
  std::vector<int> order;         // triangles grouped by component
  std::vector<int> component_of;  // per triangle (original index)
  std::vector<int> first;         // per component, into order
  std::vector<int> count;
  std::vector<bool> closed;
  std::vector<double> signed_volume;
};

void Validate(const geometry::TriangleMesh& mesh, const std::string& what) {
  for (const Eigen::Vector3d& v : mesh.vertices) {
    if (!v.allFinite()) throw common::ConfigError(what + ": vertex is not finite");
  }
  const int nv = static_cast<int>(mesh.vertices.size());
  for (const auto& t : mesh.triangles) {
    for (int i : t) {
      if (i < 0 || i >= nv) {
        throw common::ConfigError(what + ": triangle index " + std::to_string(i) +
                                  " out of range (" + std::to_string(nv) + " vertices)");
      }
    }
  }
}

int Find(std::vector<int>& parent, int a) {
  while (parent[a] != a) {
    parent[a] = parent[parent[a]];
    a = parent[a];
  }
  return a;
}

MeshAnalysis Analyse(const geometry::TriangleMesh& mesh) {
  const int nv = static_cast<int>(mesh.vertices.size());
  const int nt = static_cast<int>(mesh.triangles.size());
  std::vector<int> parent(nv);
  for (int i = 0; i < nv; ++i) parent[i] = i;
  for (const auto& t : mesh.triangles) {
    parent[Find(parent, t[1])] = Find(parent, t[0]);
    parent[Find(parent, t[2])] = Find(parent, t[0]);
  }
  MeshAnalysis a;
  std::vector<int> root_component(nv, -1);
  a.component_of.resize(nt);
  for (int t = 0; t < nt; ++t) {
    const int root = Find(parent, mesh.triangles[t][0]);
    if (root_component[root] < 0) {
      root_component[root] = static_cast<int>(a.first.size());
      a.first.push_back(0);
      a.count.push_back(0);
    }
    a.component_of[t] = root_component[root];
    ++a.count[a.component_of[t]];
  }
  const int nc = static_cast<int>(a.count.size());
  for (int c = 1; c < nc; ++c) a.first[c] = a.first[c - 1] + a.count[c - 1];
  a.order.resize(nt);
  std::vector<int> fill(a.first);
  for (int t = 0; t < nt; ++t) a.order[fill[a.component_of[t]]++] = t;
  // Closed: every directed edge once, and its reverse once.
  std::vector<std::uint64_t> edges;
  edges.reserve(3 * static_cast<size_t>(nt));
  for (const auto& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) {
      edges.push_back((static_cast<std::uint64_t>(t[i]) << 32) |
                      static_cast<std::uint32_t>(t[(i + 1) % 3]));
    }
  }
  std::sort(edges.begin(), edges.end());
  a.closed.assign(nc, true);
  for (size_t i = 0; i < edges.size(); ++i) {
    const auto from = static_cast<int>(edges[i] >> 32);
    const auto to = static_cast<int>(edges[i] & 0xffffffffU);
    const bool duplicate = (i + 1 < edges.size() && edges[i + 1] == edges[i]);
    const std::uint64_t reverse =
        (static_cast<std::uint64_t>(to) << 32) | static_cast<std::uint32_t>(from);
    const auto it = std::lower_bound(edges.begin(), edges.end(), reverse);
    const bool has_reverse =
        it != edges.end() && *it == reverse && (it + 1 == edges.end() || *(it + 1) != reverse);
    if (duplicate || !has_reverse || from == to) {
      a.closed[root_component[Find(parent, from)]] = false;
    }
  }
  a.signed_volume.assign(nc, 0.0);
  for (int c = 0; c < nc; ++c) {
    const Eigen::Vector3d origin = mesh.vertices[mesh.triangles[a.order[a.first[c]]][0]];
    double v6 = 0;
    for (int k = a.first[c]; k < a.first[c] + a.count[c]; ++k) {
      const auto& t = mesh.triangles[a.order[k]];
      v6 += (mesh.vertices[t[0]] - origin)
                .dot((mesh.vertices[t[1]] - origin).cross(mesh.vertices[t[2]] - origin));
    }
    a.signed_volume[c] = v6 / 6.0;
  }
  return a;
}

// Rebuilds `mesh` with triangles grouped by component and closed components
// turned outwards.
geometry::TriangleMesh Reorder(const geometry::TriangleMesh& mesh, const MeshAnalysis& a) {
  geometry::TriangleMesh out;
  out.vertices = mesh.vertices;
  out.triangles.reserve(mesh.triangles.size());
  for (int t : a.order) {
    auto tri = mesh.triangles[t];
    const int c = a.component_of[t];
    if (a.closed[c] && a.signed_volume[c] < 0) std::swap(tri[1], tri[2]);
    out.triangles.push_back(tri);
  }
  return out;
}

bool IsConvexComponent(const geometry::TriangleMesh& mesh, int first, int count) {
  // Vertex set of the component.
  std::vector<int> verts;
  for (int t = first; t < first + count; ++t) {
    verts.insert(verts.end(), mesh.triangles[t].begin(), mesh.triangles[t].end());
  }
  std::sort(verts.begin(), verts.end());
  verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
  if (static_cast<double>(verts.size()) * count > 4e6) return false;
  double scale = 0;
  for (int v : verts) scale = std::max(scale, mesh.vertices[v].cwiseAbs().maxCoeff());
  for (int t = first; t < first + count; ++t) {
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector3d& p0 = mesh.vertices[tri[0]];
    const Eigen::Vector3d n = (mesh.vertices[tri[1]] - p0).cross(mesh.vertices[tri[2]] - p0);
    const double len = n.norm();
    if (len == 0) continue;
    for (int v : verts) {
      if (n.dot(mesh.vertices[v] - p0) > 1e-9 * len * std::max(scale, 1.0)) return false;
    }
  }
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------

CameraPose CameraPose::FromModel(const geometry::CameraModel& camera) {
  return {camera.CentreW(), camera.R_CW.transpose()};
}

CameraPose CameraPose::LookAt(const Eigen::Vector3d& position_W, const Eigen::Vector3d& target_W,
                              const Eigen::Vector3d& up_W) {
  const Eigen::Vector3d z = (target_W - position_W).normalized();
  const Eigen::Vector3d x = z.cross(up_W).normalized();
  const Eigen::Vector3d y = z.cross(x);
  CameraPose pose;
  pose.position_W = position_W;
  pose.R_WC.col(0) = x;
  pose.R_WC.col(1) = y;
  pose.R_WC.col(2) = z;
  return pose;
}

Intrinsics Intrinsics::FromModel(const geometry::CameraModel& camera) {
  return {camera.width, camera.height, camera.K};
}

OccluderMesh::OccluderMesh(const geometry::TriangleMesh& mesh) {
  Validate(mesh, "obstacle mesh");
  const MeshAnalysis a = Analyse(mesh);
  mesh_ = Reorder(mesh, a);
  const int nc = static_cast<int>(a.count.size());
  components_.resize(nc);
  triangle_component_.resize(mesh_.triangles.size());
  for (int c = 0; c < nc; ++c) {
    Component& comp = components_[c];
    // A closed surface without volume has no inside to cull back faces by.
    comp.closed = a.closed[c] && a.signed_volume[c] != 0.0;
    comp.convex = comp.closed && IsConvexComponent(mesh_, a.first[c], a.count[c]);
    comp.first_triangle = a.first[c];
    comp.num_triangles = a.count[c];
    comp.bounds.min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    comp.bounds.max = -comp.bounds.min;
    for (int t = a.first[c]; t < a.first[c] + a.count[c]; ++t) {
      triangle_component_[t] = c;
      for (int v : mesh_.triangles[t]) {
        comp.bounds.min = comp.bounds.min.cwiseMin(mesh_.vertices[v]);
        comp.bounds.max = comp.bounds.max.cwiseMax(mesh_.vertices[v]);
      }
    }
  }
}

FovScene::FovScene(const geometry::TriangleMesh& cell, const geometry::TriangleMesh& obstacles)
    : obstacles_(obstacles) {
  Validate(cell, "cell mesh");
  if (cell.triangles.empty()) throw common::ConfigError("cell mesh: no triangles");
  const MeshAnalysis a = Analyse(cell);
  for (size_t c = 0; c < a.closed.size(); ++c) {
    if (!a.closed[c]) {
      throw common::ConfigError("cell mesh: not closed (every edge must join two triangles)");
    }
    if (!(std::abs(a.signed_volume[c]) > 0)) {
      throw common::ConfigError("cell mesh: a component has no volume");
    }
    cell_volume_m3_ += std::abs(a.signed_volume[c]);
  }
  cell_ = Reorder(cell, a);
  cell_bounds_.min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  cell_bounds_.max = -cell_bounds_.min;
  for (const auto& t : cell_.triangles) {
    for (int v : t) {
      cell_bounds_.min = cell_bounds_.min.cwiseMin(cell_.vertices[v]);
      cell_bounds_.max = cell_bounds_.max.cwiseMax(cell_.vertices[v]);
    }
  }
}

namespace {
geometry::TriangleMesh BoxMesh(const common::Box3& box) {
  if (!box.IsValid() || !box.min.allFinite() || !box.max.allFinite()) {
    throw common::ConfigError("cell: bounds: max must exceed min on every axis");
  }
  return geometry::TriangleMesh::Box(box.min, box.max);
}
}  // namespace

FovScene::FovScene(const common::Box3& cell, const geometry::TriangleMesh& obstacles)
    : FovScene(BoxMesh(cell), obstacles) {}

// ---------------------------------------------------------------------------

struct FovEvaluator::Impl {
  Workspace<double> ws_double;
  Workspace<Ad> ws_ad;
};

namespace {

template <typename S>
void AddObstacleFaces(const OccluderMesh& occ, const std::vector<P3<S>>& pts, int component_offset,
                      const Eigen::Vector3d& camera_W, const Frustum& fr, Workspace<S>* ws) {
  const auto& mesh = occ.mesh();
  for (int c = 0; c < occ.NumComponents(); ++c) {
    const auto& comp = occ.component(c);
    int keep = 0;
    if (comp.closed) {
      keep = 1;
      const Eigen::Vector3d margin = Eigen::Vector3d::Constant(1e-9);
      if ((camera_W.array() >= (comp.bounds.min - margin).array()).all() &&
          (camera_W.array() <= (comp.bounds.max + margin).array()).all() &&
          WindingNumber(mesh, comp.first_triangle, comp.num_triangles, camera_W) > 0.5) {
        keep = -1;  // Seen from inside: the faces turned away from the camera.
      }
    }
    const int gc = component_offset + c;
    ws->keep[gc] = keep;
    ws->convex[gc] = comp.convex ? 1 : 0;
    ws->first_face[gc] = static_cast<int>(ws->faces.size());
    Bbox box{1, 1, 0, 0};
    double zmin = std::numeric_limits<double>::infinity();
    for (int t = comp.first_triangle; t < comp.first_triangle + comp.num_triangles; ++t) {
      const auto& tri = mesh.triangles[t];
      Face<S> face;
      int d_sign = 0;
      if (!PrepareFace(pts[tri[0]], pts[tri[1]], pts[tri[2]], fr, keep, ws, &face, &d_sign)) {
        continue;
      }
      face.component = gc;
      face.id = static_cast<int>(ws->faces.size());
      if (face.id == ws->first_face[gc]) {
        box = face.box;
      } else {
        box = {std::min(box.u0, face.box.u0), std::min(box.v0, face.box.v0),
               std::max(box.u1, face.box.u1), std::max(box.v1, face.box.v1)};
      }
      zmin = std::min(zmin, face.zmin);
      ws->faces.push_back(face);
    }
    ws->end_face[gc] = static_cast<int>(ws->faces.size());
    ws->comp_box[gc] = box;
    ws->comp_zmin[gc] = zmin;
  }
}

template <typename S>
S Evaluate(const FovScene& scene, const CameraPose& pose, const Intrinsics& intrinsics,
           const OccluderMesh* object, Workspace<S>* ws, FovStats* stats) {
  const Frustum fr = MakeFrustum(intrinsics);
  *stats = FovStats{};
  ToCamera(scene.cell().vertices, pose, &ws->cell_pts);
  ToCamera(scene.obstacles().mesh().vertices, pose, &ws->obstacle_pts);
  ws->face_pts.clear();
  ws->face_lines.clear();
  ws->cell_faces.clear();
  ws->faces.clear();

  // Cell boundary, both sides.
  for (const auto& tri : scene.cell().triangles) {
    Face<S> face;
    int d_sign = 0;
    if (!PrepareFace(ws->cell_pts[tri[0]], ws->cell_pts[tri[1]], ws->cell_pts[tri[2]], fr, 0, ws,
                     &face, &d_sign)) {
      continue;
    }
    face.sign = d_sign;
    ws->cell_faces.push_back(face);
  }
  stats->cell_faces = static_cast<int>(ws->cell_faces.size());

  S volume(0.0);
  for (const Face<S>& t : ws->cell_faces) {
    volume += static_cast<double>(t.sign) * ConeVolume(ws->face_pts.data() + t.begin, t.count, t.m);
  }
  if (ws->cell_faces.empty()) return volume;

  // Obstacle faces (scene, then object).
  const int n_scene_components = scene.obstacles().NumComponents();
  const int n_components = n_scene_components + (object ? object->NumComponents() : 0);
  ws->keep.assign(n_components, 0);
  ws->convex.assign(n_components, 0);
  ws->first_face.assign(n_components, 0);
  ws->end_face.assign(n_components, 0);
  ws->comp_box.resize(n_components);
  ws->comp_zmin.resize(n_components);
  AddObstacleFaces(scene.obstacles(), ws->obstacle_pts, 0, pose.position_W, fr, ws);
  if (object != nullptr) {
    ToCamera(object->mesh().vertices, pose, &ws->object_pts);
    AddObstacleFaces(*object, ws->object_pts, n_scene_components, pose.position_W, fr, ws);
  }
  const int nf = static_cast<int>(ws->faces.size());
  stats->obstacle_faces = nf;
  if (nf == 0) return volume;

  // Occluder candidates of a face come from a loop over the components (their
  // image bounds and depth reject most at once) and, for the faces of large
  // components, from an image grid.
  const auto is_large = [&](int c) {
    return ws->end_face[c] - ws->first_face[c] > kLargeComponent;
  };
  int n_grid = 0;
  for (int c = 0; c < n_components; ++c) {
    if (is_large(c)) n_grid += ws->end_face[c] - ws->first_face[c];
  }
  const int gn = std::clamp(static_cast<int>(std::sqrt(n_grid / 2.0)), 1, 64);
  const double gu = gn / std::max(fr.box.u1 - fr.box.u0, 1e-300);
  const double gv = gn / std::max(fr.box.v1 - fr.box.v0, 1e-300);
  const auto cell_range = [&](const Bbox& b, int* i0, int* i1, int* j0, int* j1) {
    *i0 = std::clamp(static_cast<int>((b.u0 - fr.box.u0) * gu), 0, gn - 1);
    *i1 = std::clamp(static_cast<int>((b.u1 - fr.box.u0) * gu), 0, gn - 1);
    *j0 = std::clamp(static_cast<int>((b.v0 - fr.box.v0) * gv), 0, gn - 1);
    *j1 = std::clamp(static_cast<int>((b.v1 - fr.box.v0) * gv), 0, gn - 1);
  };
  ws->grid_start.assign(gn * gn + 1, 0);
  ws->grid_items.clear();
  if (n_grid > 0) {
    for (int c = 0; c < n_components; ++c) {
      if (!is_large(c)) continue;
      for (int k = ws->first_face[c]; k < ws->end_face[c]; ++k) {
        int i0, i1, j0, j1;
        cell_range(ws->faces[k].box, &i0, &i1, &j0, &j1);
        for (int j = j0; j <= j1; ++j) {
          for (int i = i0; i <= i1; ++i) ++ws->grid_start[j * gn + i + 1];
        }
      }
    }
    for (int c = 0; c < gn * gn; ++c) ws->grid_start[c + 1] += ws->grid_start[c];
    ws->grid_items.resize(ws->grid_start[gn * gn]);
    ws->candidates.assign(ws->grid_start.begin(), ws->grid_start.end() - 1);  // fill cursors
    for (int c = 0; c < n_components; ++c) {
      if (!is_large(c)) continue;
      for (int k = ws->first_face[c]; k < ws->end_face[c]; ++k) {
        int i0, i1, j0, j1;
        cell_range(ws->faces[k].box, &i0, &i1, &j0, &j1);
        for (int j = j0; j <= j1; ++j) {
          for (int i = i0; i <= i1; ++i) ws->grid_items[ws->candidates[j * gn + i]++] = k;
        }
      }
    }
  }
  ws->stamp.assign(nf, -1);

  PieceSet<S>* vis = &ws->seen;
  for (int k = 0; k < nf; ++k) {
    const Face<S>& face = ws->faces[k];
    // Cell triangles that may lie behind this face: only through them does the
    // face change the seen volume.
    ws->cell_candidates.clear();
    for (int c = 0; c < static_cast<int>(ws->cell_faces.size()); ++c) {
      const Face<S>& t = ws->cell_faces[c];
      if (t.zmax >= face.zmin && t.box.Overlaps(face.box)) ws->cell_candidates.push_back(c);
    }
    if (ws->cell_candidates.empty()) continue;

    const P2<S>* fp = ws->face_pts.data() + face.begin;
    vis->Clear();
    vis->Add(fp, ws->face_lines.data() + face.begin, face.count, face.box);
    // Occluders: every face nearer somewhere over this footprint.
    ws->candidates.clear();
    const auto worth = [&](const Face<S>& other) {
      return other.zmin <= face.zmax && other.box.Overlaps(face.box);
    };
    for (int c = 0; c < n_components; ++c) {
      if (is_large(c) || (c == face.component && ws->convex[c])) continue;
      if (ws->comp_zmin[c] > face.zmax || !ws->comp_box[c].Overlaps(face.box)) continue;
      for (int g = ws->first_face[c]; g < ws->end_face[c]; ++g) {
        if (g != k && worth(ws->faces[g])) ws->candidates.push_back(g);
      }
    }
    if (n_grid > 0) {
      int i0, i1, j0, j1;
      cell_range(face.box, &i0, &i1, &j0, &j1);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          for (int s = ws->grid_start[j * gn + i]; s < ws->grid_start[j * gn + i + 1]; ++s) {
            const int g = ws->grid_items[s];
            if (ws->stamp[g] == k) continue;
            ws->stamp[g] = k;
            const Face<S>& other = ws->faces[g];
            if (g == k || (other.component == face.component && ws->convex[face.component])) {
              continue;
            }
            if (worth(other)) ws->candidates.push_back(g);
          }
        }
      }
    }
    for (int g : ws->candidates) {
      const Face<S>& other = ws->faces[g];
      Line<S> line;
      const DepthRelation rel = Relate(face, other, fp, &line);
      bool made = false;
      switch (rel) {
        case DepthRelation::kNowhereNearer:
          break;
        case DepthRelation::kCoplanar:
          if (other.id < face.id)
            made = MakeOccluder(other, static_cast<Line<S>*>(nullptr), fr.min_area, ws);
          break;
        case DepthRelation::kEverywhereNearerOrEqual:
          made = MakeOccluder(other, static_cast<Line<S>*>(nullptr), fr.min_area, ws);
          break;
        case DepthRelation::kSplit:
          made = MakeOccluder(other, &line, fr.min_area, ws);
          break;
      }
      if (!made) continue;
      Subtract(BoundsOf(ws->occluder.p.data(), ws->occluder.size()), fr.min_area, ws, vis);
      ++stats->subtractions;
      stats->max_pieces = std::max(stats->max_pieces, vis->alive);
      if (vis->alive == 0) break;
    }
    if (vis->alive == 0) continue;

    // The seen part of the face ends the rays there: the cell crossings behind
    // it go, the face's own depth comes in with their signs.
    for (int c : ws->cell_candidates) {
      const Face<S>& t = ws->cell_faces[c];
      // Behind-or-equal: m_t . w <= m_face . w.
      Line<S> line;
      const DepthRelation rel = Relate(face, t, fp, &line);
      if (rel == DepthRelation::kSplit) {
        line = {-line.a, -line.b, -line.c};
      } else if (rel == DepthRelation::kEverywhereNearerOrEqual) {
        // t is nearer (or equal) everywhere: it only counts where equal, a
        // null set unless coplanar (handled below).
        continue;
      }
      const bool cut = rel == DepthRelation::kSplit;
      for (const PieceRef& piece : vis->pieces) {
        if (piece.count == 0 || !piece.box.Overlaps(t.box)) continue;
        Poly2<S>* cur = &ws->poly_a;
        cur->p.assign(vis->pts.data() + piece.begin, vis->pts.data() + piece.begin + piece.count);
        cur->l.assign(vis->lines.data() + piece.begin,
                      vis->lines.data() + piece.begin + piece.count);
        bool empty = false;
        for (int e = 0; e < t.count + (cut ? 1 : 0) && !empty; ++e) {
          const Line<S>& l = e < t.count ? ws->face_lines[t.begin + e] : line;
          const Side side = Split(cur->p.data(), cur->l.data(), cur->size(), l, &ws->poly_b,
                                  static_cast<Poly2<S>*>(nullptr), &ws->f);
          if (side == Side::kIn) continue;
          empty = side == Side::kOut || ws->poly_b.size() < 3;
          std::swap(*cur, ws->poly_b);
        }
        if (empty) continue;
        const int n = cur->size();
        if (SignedArea(cur->p.data(), n) <= fr.min_area) continue;
        volume += static_cast<double>(t.sign) *
                  (ConeVolume(cur->p.data(), n, face.m) - ConeVolume(cur->p.data(), n, t.m));
      }
    }
  }
  return volume;
}

}  // namespace

FovEvaluator::FovEvaluator() : impl_(std::make_unique<Impl>()) {}
FovEvaluator::~FovEvaluator() = default;
FovEvaluator::FovEvaluator(FovEvaluator&&) noexcept = default;
FovEvaluator& FovEvaluator::operator=(FovEvaluator&&) noexcept = default;

double FovEvaluator::Volume(const FovScene& scene, const CameraPose& pose,
                            const Intrinsics& intrinsics, const OccluderMesh* object) {
  return Evaluate(scene, pose, intrinsics, object, &impl_->ws_double, &stats_);
}

VolumeGradient FovEvaluator::VolumeAndGradient(const FovScene& scene, const CameraPose& pose,
                                               const Intrinsics& intrinsics,
                                               const OccluderMesh* object) {
  const Ad v = Evaluate(scene, pose, intrinsics, object, &impl_->ws_ad, &stats_);
  VolumeGradient out;
  out.volume_m3 = v.value();
  if (v.derivatives().size() == 6) out.gradient = v.derivatives();
  return out;
}

double FovVolume(const FovScene& scene, const geometry::CameraModel& camera) {
  FovEvaluator evaluator;
  return evaluator.Volume(scene, CameraPose::FromModel(camera), Intrinsics::FromModel(camera));
}

double ObjectFreeVolume(const FovScene& scene, const geometry::CameraModel& camera,
                        const OccluderMesh& object) {
  FovEvaluator evaluator;
  return evaluator.Volume(scene, CameraPose::FromModel(camera), Intrinsics::FromModel(camera),
                          &object);
}

double RotationParameterDerivative(const Eigen::Matrix3d& R_WC, const Eigen::Matrix3d& dR_WC,
                                   const Eigen::Vector3d& grad_delta) {
  const Eigen::Matrix3d omega = R_WC.transpose() * dR_WC;  // skew: [w]x
  const Eigen::Vector3d w(0.5 * (omega(2, 1) - omega(1, 2)), 0.5 * (omega(0, 2) - omega(2, 0)),
                          0.5 * (omega(1, 0) - omega(0, 1)));
  return grad_delta.dot(w);
}

// ---------------------------------------------------------------------------

geometry::TriangleMesh CapsuleHullMesh(const Capsule& capsule, int segments) {
  if (!capsule.a_W.allFinite() || !capsule.b_W.allFinite() || !std::isfinite(capsule.radius_m)) {
    throw common::ConfigError("capsule: end points and radius must be finite");
  }
  if (!(capsule.radius_m > 0)) throw common::ConfigError("capsule: radius must be positive");
  if (segments < 4) throw common::ConfigError("capsule: segments must be at least 4");
  const int n_lon = segments;
  const int n_half = std::max(1, segments / 4);  // rings from the equator up, below the pole
  // Axis frame.
  Eigen::Vector3d axis = capsule.b_W - capsule.a_W;
  const double length = axis.norm();
  const bool sphere = !(length > 1e-12 * std::max(1.0, capsule.radius_m));
  axis = sphere ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d(axis / length);
  const Eigen::Vector3d helper =
      std::abs(axis.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e1 = axis.cross(helper).normalized();
  const Eigen::Vector3d e2 = axis.cross(e1);
  // Unit latitude-longitude polyhedron: rings at latitudes j * (pi/2) / n_half,
  // j = 0 (equator) .. n_half - 1, and the poles. Its faces' smallest distance
  // from the centre sets the scale that puts every face plane at >= radius.
  const auto unit = [&](int j, int i) {
    const double lat = j * (std::numbers::pi / 2) / n_half;
    const double lon = 2 * std::numbers::pi * i / n_lon;
    return Eigen::Vector3d(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon),
                           std::sin(lat));
  };
  const auto plane_distance = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                 const Eigen::Vector3d& c) {
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    return std::abs(n.dot(a));
  };
  double h_min = std::cos(std::numbers::pi / n_lon);  // the band along the axis
  for (int j = 0; j + 1 < n_half; ++j) {
    h_min = std::min(h_min, plane_distance(unit(j, 0), unit(j, 1), unit(j + 1, 1)));
  }
  h_min = std::min(
      h_min, plane_distance(unit(n_half - 1, 0), unit(n_half - 1, 1), Eigen::Vector3d::UnitZ()));
  const double scale = capsule.radius_m / h_min * (1.0 + 1e-9);

  geometry::TriangleMesh mesh;
  const auto world = [&](const Eigen::Vector3d& u, const Eigen::Vector3d& centre) {
    return Eigen::Vector3d(centre + scale * (u.x() * e1 + u.y() * e2 + u.z() * axis));
  };
  // Upper half around b (rings 0..n_half-1, then the pole), lower half around a.
  const auto add_half = [&](const Eigen::Vector3d& centre, double up) {
    const int base = static_cast<int>(mesh.vertices.size());
    for (int j = 0; j < n_half; ++j) {
      for (int i = 0; i < n_lon; ++i) {
        Eigen::Vector3d u = unit(j, i);
        u.z() *= up;
        mesh.vertices.push_back(world(u, centre));
      }
    }
    mesh.vertices.push_back(world(Eigen::Vector3d(0, 0, up), centre));
    return base;
  };
  const int upper = add_half(sphere ? capsule.a_W : capsule.b_W, 1.0);
  const int lower = add_half(capsule.a_W, -1.0);
  const auto ring = [&](int base, int j, int i) { return base + j * n_lon + (i % n_lon); };
  const auto quad = [&](int a, int b, int c, int d) {  // counter-clockwise from outside
    mesh.triangles.push_back({a, b, c});
    mesh.triangles.push_back({a, c, d});
  };
  for (int half = 0; half < 2; ++half) {
    const int base = half == 0 ? upper : lower;
    const int pole = base + n_half * n_lon;
    for (int i = 0; i < n_lon; ++i) {
      for (int j = 0; j + 1 < n_half; ++j) {
        if (half == 0) {
          quad(ring(base, j, i), ring(base, j, i + 1), ring(base, j + 1, i + 1),
               ring(base, j + 1, i));
        } else {
          quad(ring(base, j, i), ring(base, j + 1, i), ring(base, j + 1, i + 1),
               ring(base, j, i + 1));
        }
      }
      if (half == 0) {
        mesh.triangles.push_back({ring(base, n_half - 1, i), ring(base, n_half - 1, i + 1), pole});
      } else {
        mesh.triangles.push_back({ring(base, n_half - 1, i), pole, ring(base, n_half - 1, i + 1)});
      }
    }
  }
  // Band between the equators (degenerate for a sphere, where both coincide).
  for (int i = 0; i < n_lon; ++i) {
    quad(ring(lower, 0, i), ring(lower, 0, i + 1), ring(upper, 0, i + 1), ring(upper, 0, i));
  }
  return mesh;
}

OccluderMesh CapsulesOccluder(std::span<const Capsule> capsules, int segments) {
  geometry::TriangleMesh all;
  for (const Capsule& c : capsules) all.Append(CapsuleHullMesh(c, segments));
  return OccluderMesh(all);
}

}  // namespace hg::placement
