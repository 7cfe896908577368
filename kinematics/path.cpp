#include "kinematics/path.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fmt/format.h>
#include <limits>
#include <new>
#include <optional>
#include <type_traits>

#include "core/errors.h"

namespace flankcam {

std::string PathOptions::validate() const {
  if (!(tool_length_mm >= 0) || !std::isfinite(tool_length_mm)) return "tool_length_mm: must be >= 0";
  if (!(tolerance_mm > 0)) return "tolerance_mm: must be > 0";
  if (!(angle_tolerance_deg > 0)) return "angle_tolerance_deg: must be > 0";
  if (checks_per_block < 1) return "checks_per_block: at least 1";
  if (max_depth < 0) return "max_depth: must be >= 0";
  return {};
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kRadPerDeg = M_PI / 180;

// Cosines and sines of a pose's rotary angles (the linearisation checks step from them).
struct Trig {
  std::array<double, 2> c{1, 1}, s{0, 0};
};
Trig trig_of(const std::array<double, 2>& deg) {
  Trig t;
  for (size_t k = 0; k < 2; ++k) t.c[k] = std::cos(deg[k] * kRadPerDeg), t.s[k] = std::sin(deg[k] * kRadPerDeg);
  return t;
}

// A candidate joint solution at one pose (its index is the IK branch): angles (NaN = free).
struct Candidate {
  std::array<double, 2> deg;
  int linear_ok = -1;  // 1/0: the linear joints are within limits (unwinding does not change them); -1: a free angle, check later
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();  // at `deg` when linear_ok >= 0
};

// Why a candidate was rejected, kept as numbers and worded only when the path fails.
struct Rejection {
  int axis = -1;      // 0..2 a linear axis, 3, 4 a rotary one; -1: none
  double value = 0;   // mm or deg
  [[nodiscard]] std::string text(const Machine& m) const {
    if (axis < 0) return {};
    if (axis < 3)
      return fmt::format("{} = {:.3f} mm is outside its limits [{}, {}]", m.linear[size_t(axis)].name, value,
                         m.linear[size_t(axis)].min_mm, m.linear[size_t(axis)].max_mm);
    const RotaryAxis& a = m.rotary[size_t(axis - 3)];
    return fmt::format("rotary axis {} would need {:.3f} deg, outside its limits [{}, {}]", a.name, value, a.min_deg, a.max_deg);
  }
};

// std::round (half away from zero, sign kept) without the library call: the Viterbi pass, which
// runs on one thread, rounds eight times per pose.
inline double round_half_away(double x) {
  if (!(std::abs(x) < 0x1p52)) return std::round(x);  // large, infinite or NaN
  double t = double(static_cast<long long>(x));         // towards zero, exact
  if (std::abs(x - t) >= 0.5) t += x < 0 ? -1.0 : 1.0;  // x - t is exact
  return std::copysign(t, x);
}

// The value of angle `k` for candidate `c` nearest to `prev` that the axis allows (NaN if none).
inline double resolve(const RotaryAxis& a, double deg, double prev) {
  if (std::isnan(deg)) deg = prev;  // free: hold
  if (a.continuous) return deg + 360.0 * round_half_away((prev - deg) / 360.0);
  // Usually the nearest turn is within the limits and nearer than any other by a margin: the
  // search below would pick it.
  const double turn = round_half_away((prev - deg) / 360.0);
  if (std::abs(turn) <= 3) {
    const double v = deg + 360.0 * turn;
    if (v >= a.min_deg - 1e-9 && v <= a.max_deg + 1e-9 && std::abs(v - prev) < 179) return v;
  }
  double best = NAN;
  for (int turn = -3; turn <= 3; ++turn) {
    const double v = deg + 360.0 * turn;
    if (v < a.min_deg - 1e-9 || v > a.max_deg + 1e-9) continue;
    if (std::isnan(best) || std::abs(v - prev) < std::abs(best - prev)) best = v;
  }
  return best;
}

// At most two of anything per pose (two IK branches): no heap allocation per pose.
template <class T>
struct Two {
  std::array<T, 2> items{};
  size_t count = 0;
  [[nodiscard]] size_t size() const { return count; }
  [[nodiscard]] bool empty() const { return count == 0; }
  void push_back(T x) { items[count++] = std::move(x); }
  void assign(size_t k, const T& x) {
    count = k;
    for (size_t j = 0; j < k; ++j) items[j] = x;
  }
  T& operator[](size_t k) { return items[k]; }
  const T& operator[](size_t k) const { return items[k]; }
  [[nodiscard]] auto begin() const { return items.begin(); }
  [[nodiscard]] auto end() const { return items.begin() + long(count); }
};

// The first linear axis outside its limits at x (as a Rejection; axis -1: all within).
Rejection linear_limits(const Machine& m, const Eigen::Vector3d& x) {
  for (int k = 0; k < 3; ++k)
    if (x[k] < m.linear[k].min_mm - 1e-9 || x[k] > m.linear[k].max_mm + 1e-9) return {k, x[k]};
  return {};
}

// singularity_angle_deg(m, axis) < singular_deg, compared as cosines (cos_singular: its cosine).
bool near_singular(const Machine& m, const Eigen::Vector3d& axis, double cos_singular) {
  return singularity_cosine(m, axis) > cos_singular;
}

// n value-initialised T per pose, their pages first touched on all threads (in the static schedule
// of the loops that fill them): std::vector's value-initialisation faults them in on one thread,
// about 90 MB for 200,000 poses, and the busiest thread's time is what two cores give.
template <class T>
class PoseArray {
 public:
  explicit PoseArray(size_t n) : p_(static_cast<T*>(::operator new(std::max<size_t>(n, 1) * sizeof(T), kAlign))) {
    static_assert(std::is_trivially_destructible_v<T>, "no destructor is run");
#pragma omp parallel for schedule(static)
    for (long i = 0; i < long(n); ++i) new (p_ + i) T();
  }
  ~PoseArray() { ::operator delete(p_, kAlign); }
  PoseArray(const PoseArray&) = delete;
  PoseArray& operator=(const PoseArray&) = delete;
  T& operator[](size_t i) { return p_[i]; }
  const T& operator[](size_t i) const { return p_[i]; }

 private:
  static constexpr std::align_val_t kAlign{alignof(T) > 64 ? alignof(T) : 64};
  T* p_;
};


}  // namespace

namespace {

// The pose a fraction f of the way through a block without an intended motion: interpolate()'s
// straight tip and great-circle axis, with the turn's axis and angle found once per block (for the
// linearisation checks; inserted poses use interpolate() itself).
struct BlockSlerp {
  ToolPose p, q;
  Eigen::Vector3d w = Eigen::Vector3d::Zero();  // unit axis of the turn from p.axis to q.axis
  double angle = 0;                             // its angle, rad
  bool exact = false;                           // (nearly) opposite axes: interpolate() picks the turn
  BlockSlerp(const ToolPose& a, const ToolPose& b) : p(a), q(b) {
    const Eigen::Vector3d cr = a.axis.cross(b.axis);
    const double sn = cr.norm(), cs = a.axis.dot(b.axis);
    if (cs < 0 && sn < 1e-6) exact = true;
    else if (sn > 0) w = cr / sn, angle = std::atan2(sn, cs);
  }
  [[nodiscard]] ToolPose at(double f) const {
    if (exact) return interpolate(p, q, f);
    ToolPose r;
    r.tip = (1 - f) * p.tip + f * q.tip;
    if (angle == 0) {
      r.axis = ((1 - f) * p.axis + f * q.axis).normalized();
    } else {
      const double c = std::cos(f * angle), s = std::sin(f * angle);
      r.axis = c * p.axis + s * w.cross(p.axis) + ((1 - c) * w.dot(p.axis)) * w;
    }
    return r;
  }
};

}  // namespace

JointPath solve_path(const Machine& m, const std::vector<ToolPose>& poses, std::vector<double> t, const PathOptions& o,
                     const IntendedMotion& motion) {
  if (auto err = o.validate(); !err.empty()) throw InputError("path options: " + err);
  const int n = int(poses.size());
  if (t.empty())
    for (int i = 0; i < n; ++i) t.push_back(i);
  if (int(t.size()) != n) throw InputError("solve_path: one parameter per pose");
  JointPath out;
  if (n == 0) return out;

  // Candidates per pose within the rotary limits (any turn), independent of the predecessor.
  const double cos_singular = std::cos(o.singular_deg * kRadPerDeg);
  PoseArray<Two<Candidate>> cand(static_cast<size_t>(n));
  PoseArray<Two<Rejection>> cand_linear(static_cast<size_t>(n));  // per candidate when linear_ok == 0
  // Cosines and sines of each candidate's angles when linear_ok >= 0 (apart: the serial Viterbi
  // pass below streams through `cand`, which stays small).
  PoseArray<std::array<Trig, 2>> cand_trig(static_cast<size_t>(n));
  std::vector<char> singular(static_cast<size_t>(n), 0);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    cand_linear[i].assign(2, Rejection{});
    for (const RotarySolution& s : rotary_solution_pair(m, poses[i].axis)) {
      Candidate c{s.deg, -1, Eigen::Vector3d::Zero()};
      for (int k = 0; k < 2; ++k)
        if (s.free[k]) c.deg[k] = NAN, singular[i] = 1;
      if (!s.free[0] && !s.free[1]) {
        const Trig& tr = cand_trig[size_t(i)][cand[i].size()] = trig_of(s.deg);
        c.linear = linear_joints(m, poses[i], tr.c, tr.s, o.tool_length_mm);
        cand_linear[i][cand[i].size()] = linear_limits(m, c.linear);
        c.linear_ok = cand_linear[i][cand[i].size()].axis < 0 ? 1 : 0;
      }
      cand[i].push_back(c);
    }
    if (near_singular(m, poses[i].axis, cos_singular)) singular[i] = 1;
  }
  for (int i = 0; i < n; ++i) {
    if (cand[i].empty()) {
      out.reachable = false;
      out.failed_pose = i;
      out.why = "the tool axis is beyond the tilt range of the rotary axes";
      return out;
    }
  }

  // Viterbi over candidates: cost = rotary travel in minutes at the axes' maximum speeds. A change of
  // IK branch between two poses whose joint interpolation leaves the intended axis by more than the
  // angle tolerance (A through 0 while the motion passes the vertical farther off than that: no
  // splitting of the block brings it back) costs kBadFlip minutes: the path stays on its branch and
  // turns C instead, unless nothing else reaches.
  const PreparedForward fk = prepare_forward(m, o.tool_length_mm);
  // The tool axis the rotary angles give (forward kinematics without the linear axes).
  const auto axis_of = [&](const std::array<double, 2>& deg) {
    const Trig tr = trig_of(deg);
    return forward(fk, Eigen::Vector3d::Zero(), tr.c, tr.s).axis;
  };
  const double cos_flip = std::cos(o.angle_tolerance_deg * kRadPerDeg);
  constexpr double kBadFlip = 1e6;
  const auto flip_leaves_axis = [&](int i, const std::array<double, 2>& from, const std::array<double, 2>& to) {
    const BlockSlerp slerp(poses[size_t(i - 1)], poses[size_t(i)]);
    for (const double f : {0.25, 0.5, 0.75}) {
      std::array<double, 2> deg{};
      for (size_t k = 0; k < 2; ++k) deg[k] = (1 - f) * from[k] + f * to[k];
      const Eigen::Vector3d want = motion ? motion((1 - f) * t[size_t(i - 1)] + f * t[size_t(i)]).axis : slerp.at(f).axis;
      if (axis_of(deg).dot(want.normalized()) < cos_flip) return true;
    }
    return false;
  };
  struct State {
    double cost = kInf;
    std::array<double, 2> deg{0, 0};
    int from = -1;
  };
  PoseArray<Two<State>> st(static_cast<size_t>(n));
  Rejection why;  // the last rejection met (worded only if the path fails)
  for (int i = 0; i < n; ++i) {
    st[i].assign(cand[i].size(), State{});
    for (size_t c = 0; c < cand[i].size(); ++c) {
      const Candidate& cd = cand[i][c];
      const size_t preds = i == 0 ? 1 : st[i - 1].size();
      for (size_t p = 0; p < preds; ++p) {
        double base = 0;
        std::array<double, 2> prev{0, 0};
        if (i > 0) {
          base = st[i - 1][p].cost;
          if (!std::isfinite(base)) continue;
          prev = st[i - 1][p].deg;
        } else {
          // Start as close to zero as the limits allow (free angles start at 0).
          for (int k = 0; k < 2; ++k)
            prev[k] = std::isnan(cd.deg[k]) ? 0 : std::clamp(0.0, m.rotary[k].min_deg, m.rotary[k].max_deg);
        }
        std::array<double, 2> deg{};
        bool ok = true;
        double cost = base;
        for (int k = 0; k < 2 && ok; ++k) {
          const RotaryAxis& a = m.rotary[k];
          deg[k] = resolve(a, cd.deg[k], prev[k]);
          if (std::isnan(deg[k])) {
            ok = false;
            why = {3 + k, cd.deg[k]};
            break;
          }
          if (i > 0) cost += std::abs(deg[k] - prev[k]) / a.max_speed_deg_min;
        }
        if (!ok) continue;
        if (cd.linear_ok == 0) {
          why = cand_linear[i][c];
          continue;
        }
        if (cd.linear_ok < 0) {
          const Rejection r = linear_limits(m, linear_joints(m, poses[i], deg, o.tool_length_mm));
          if (r.axis >= 0) {
            why = r;
            continue;
          }
        }
        if (i > 0 && p != c && cand[i].size() > 1 && cand[i - 1].size() > 1 && cost < st[i][c].cost &&
            flip_leaves_axis(i, prev, deg))
          cost += kBadFlip;
        if (cost < st[i][c].cost) st[i][c] = {cost, deg, int(p)};
      }
    }
    if (std::none_of(st[i].begin(), st[i].end(), [](const State& s) { return std::isfinite(s.cost); })) {
      out.reachable = false;
      out.failed_pose = i;
      out.why = why.axis < 0 ? "no joint solution within the limits" : why.text(m);
      return out;
    }
  }
  // Backtrack.
  std::vector<int> pick(static_cast<size_t>(n));
  {
    // Equal costs (mirror branches travel alike): the branch whose first rotary axis ends nearer the
    // middle of its range, so that round-off in the poses never flips the choice.
    const RotaryAxis& first = m.rotary[0];
    const double mid = first.continuous ? 0 : 0.5 * (first.min_deg + first.max_deg);
    const auto off_centre = [&](const State& s) { return std::abs(s.deg[0] - mid); };
    // Only reachable states compete: an unreachable one has no cost and no angles (its unset angles
    // could look nearer the middle), and backtracking from it would read no predecessor.
    int best = -1;
    for (size_t c = 0; c < st[n - 1].size(); ++c) {
      if (!std::isfinite(st[n - 1][c].cost)) continue;
      if (best < 0) {
        best = int(c);
        continue;
      }
      const State &a = st[n - 1][c], &b = st[n - 1][size_t(best)];
      const double tie = 1e-9 * std::max(1.0, std::abs(b.cost));
      if (a.cost < b.cost - tie || (std::abs(a.cost - b.cost) <= tie && off_centre(a) < off_centre(b) - 1e-9)) best = int(c);
    }
    for (int i = n - 1; i >= 0; --i) {
      pick[i] = best;
      best = st[i][best].from;
    }
  }
  PoseArray<Joints> q(static_cast<size_t>(n));
  std::vector<char> free_angle(static_cast<size_t>(n));  // bit k: angle k is free at the chosen candidate
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    q[i].rotary = st[i][size_t(pick[i])].deg;
    const Candidate& c = cand[i][size_t(pick[i])];
    free_angle[size_t(i)] = char((std::isnan(c.deg[0]) ? 1 : 0) | (std::isnan(c.deg[1]) ? 2 : 0));
  }
  // Free angles: interpolate across each singular run between its defined neighbours.
  for (int k = 0; k < 2; ++k) {
    for (int i = 0; i < n;) {
      if (!(free_angle[size_t(i)] >> k & 1)) {
        ++i;
        continue;
      }
      int j = i;
      while (j < n && (free_angle[size_t(j)] >> k & 1)) ++j;
      const bool has_before = i > 0, has_after = j < n;
      for (int r = i; r < j; ++r) {
        double v = q[r].rotary[k];
        if (has_before && has_after) {
          const double f = (t[r] - t[i - 1]) / (t[j] - t[i - 1]);
          v = (1 - f) * q[i - 1].rotary[k] + f * q[j].rotary[k];
        } else if (has_after) {
          v = q[j].rotary[k];
        }
        q[r].rotary[k] = v;
      }
      i = j;
    }
  }
  PoseArray<Trig> trig(static_cast<size_t>(n));
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    // The candidate's linear joints when the chosen angles are its own, bit for bit (no turn added).
    const Candidate& c = cand[i][size_t(pick[i])];
    if (c.linear_ok >= 0 && std::memcmp(c.deg.data(), q[i].rotary.data(), sizeof c.deg) == 0) {
      q[i].linear = c.linear;
      trig[i] = cand_trig[size_t(i)][size_t(pick[i])];
    } else {
      trig[i] = trig_of(q[i].rotary);
      q[i].linear = linear_joints(m, poses[i], trig[i].c, trig[i].s, o.tool_length_mm);
    }
  }
  int branch_changes = 0;
#pragma omp parallel for schedule(static) reduction(+ : branch_changes)
  for (int i = 1; i < n; ++i) {
    if (cand[i].size() > 1 && cand[i - 1].size() > 1 && !singular[i] && !singular[i - 1] && pick[i] != pick[i - 1])
      ++branch_changes;
  }
  out.branch_changes = branch_changes;

  // Linearisation by recursive bisection of each block.
  // The checks sample each block at a few points; the error between them peaks a few percent higher
  // (measured up to 4%), so the blocks are held to 90% of the tolerance.
  const double tip_tol2 = std::pow(0.9 * o.tolerance_mm, 2), cos_tol = std::cos(0.9 * o.angle_tolerance_deg * kRadPerDeg);
  const double cos_node = std::cos(0.8 * o.angle_tolerance_deg * kRadPerDeg), cos_zone = std::cos(20 * o.angle_tolerance_deg * kRadPerDeg);
  // The solution of a pose inserted a fraction f of the way from joints `a` to `b` (unwound like `a`)
  // with the least rotary travel from a to it and on to b. Nearest to `a` alone is not enough: just
  // past a near-singular pose the branch nearest `a` can be the mirror of b's, and the sub-block
  // left between them turns C by 180 deg while A changes sign, the same axis at both ends (the
  // table swings the part under the tool).
  const auto between = [&](const ToolPose& p, const Joints& a, const Joints& b, double f) -> std::optional<Joints> {
    // Near the singular direction the exact solutions' free-ish angle swings fast (C turns 180 deg
    // while the axis passes the vertical) and means little: each solution is moved toward the angles
    // interpolated from a to b as far as its axis stays within 0.8 of the angle tolerance, so a motion
    // passing the vertical closer than that crosses A = 0 without C turning, and C joins its exact
    // values smoothly beyond.
    const bool near_singular_axis = singularity_cosine(m, p.axis) > cos_zone;
    std::optional<Joints> best;
    double best_d = kInf;
    for (const RotarySolution& s : rotary_solution_pair(m, p.axis)) {
      Joints j;
      bool ok = true;
      std::array<double, 2> towards{};
      for (int k = 0; k < 2; ++k) {
        towards[size_t(k)] = (1 - f) * a.rotary[k] + f * b.rotary[k];
        const double v = s.free[k] ? towards[size_t(k)] : resolve(m.rotary[k], s.deg[k], a.rotary[k]);
        if (std::isnan(v)) ok = false;
        j.rotary[k] = v;
      }
      if (!ok) continue;
      if (near_singular_axis) {
        const std::array<double, 2> exact = j.rotary;
        const auto moved = [&](double lambda) {
          std::array<double, 2> d{};
          for (size_t k = 0; k < 2; ++k) d[k] = exact[k] + lambda * (towards[k] - exact[k]);
          return d;
        };
        double lo = 0, hi = 1;
        if (axis_of(moved(1)).dot(p.axis) >= cos_node) lo = 1;
        else
          for (int it = 0; it < 24; ++it) {
            const double mid = 0.5 * (lo + hi);
            (axis_of(moved(mid)).dot(p.axis) >= cos_node ? lo : hi) = mid;
          }
        j.rotary = moved(lo);
      }
      double d = 0;
      for (int k = 0; k < 2; ++k)
        d += near_singular_axis ? std::abs(j.rotary[k] - towards[size_t(k)])
                                : std::abs(j.rotary[k] - a.rotary[k]) + std::abs(b.rotary[k] - j.rotary[k]);
      if (d >= best_d) continue;
      j.linear = linear_joints(m, p, j.rotary, o.tool_length_mm);
      if (linear_limits(m, j.linear).axis >= 0) continue;
      best_d = d;
      best = j;
    }
    return best;
  };
  struct Node {
    double t;
    ToolPose pose;
    Joints q;
    Trig trig;
  };
  // One block (input poses i0, i0 + 1) and its sub-blocks; inserted poses go to `acc` in order,
  // `unresolved` counts sub-blocks left off tolerance.
  struct Block {
    int i0;
    std::optional<BlockSlerp> slerp;  // without an intended motion
    std::vector<Node>& acc;
    int& unresolved;
  };
  const auto intended_at = [&](const Block& b, double tt, bool exact) {
    if (motion) return motion(tt);
    const double f = (tt - t[b.i0]) / (t[b.i0 + 1] - t[b.i0]);
    return exact ? interpolate(poses[b.i0], poses[b.i0 + 1], f) : b.slerp->at(f);
  };
  // FK at checks_per_block evenly spaced points of the joint interpolation from a to b (the
  // controller interpolates joints linearly), the rotary angles stepped by a rotation of their
  // cosines and sines, against the intended poses there.
  const auto off_tolerance = [&](const Block& blk, const Node& a, const Node& b) {
    const double g = 1.0 / (o.checks_per_block + 1);
    std::array<double, 2> dc{}, ds{};
    for (size_t k = 0; k < 2; ++k) {
      const double step = (b.q.rotary[k] - a.q.rotary[k]) * g * kRadPerDeg;
      dc[k] = std::cos(step), ds[k] = std::sin(step);
    }
    Trig at = a.trig;
    for (int s = 1; s <= o.checks_per_block; ++s) {
      const double f = double(s) / (o.checks_per_block + 1);
      for (size_t k = 0; k < 2; ++k) {
        const double c = at.c[k] * dc[k] - at.s[k] * ds[k], sn = at.s[k] * dc[k] + at.c[k] * ds[k];
        at.c[k] = c, at.s[k] = sn;
      }
      const ToolPose got = forward(fk, (1 - f) * a.q.linear + f * b.q.linear, at.c, at.s);
      const ToolPose want = intended_at(blk, (1 - f) * a.t + f * b.t, false);
      if ((got.tip - want.tip).squaredNorm() > tip_tol2 || got.axis.dot(want.axis) < cos_tol) return true;
    }
    return false;
  };
  const auto split = [&](const auto& self, const Block& blk, const Node& a, const Node& b, int depth) -> void {
    if (!off_tolerance(blk, a, b)) return;
    if (depth >= o.max_depth) {
      ++blk.unresolved;
      return;
    }
    const double tm = 0.5 * (a.t + b.t);
    const ToolPose pm = intended_at(blk, tm, true);
    const std::optional<Joints> qm = between(pm, a.q, b.q, 0.5);
    if (!qm) {
      ++blk.unresolved;
      return;
    }
    const Node mid{tm, pm, *qm, trig_of(qm->rotary)};
    self(self, blk, a, mid, depth + 1);
    blk.acc.push_back(mid);
    self(self, blk, mid, b, depth + 1);
  };
  // Blocks are independent: split them in parallel, merge in order (deterministic).
  std::vector<std::vector<Node>> inserted(static_cast<size_t>(n));
  std::vector<int> unresolved(static_cast<size_t>(n), 0);
#pragma omp parallel for schedule(dynamic, 256)
  for (int i = 1; i < n; ++i) {
    Block blk{i - 1, std::nullopt, inserted[size_t(i)], unresolved[size_t(i)]};
    if (!motion) blk.slerp.emplace(poses[size_t(i - 1)], poses[size_t(i)]);
    split(split, blk, {t[i - 1], poses[i - 1], q[i - 1], trig[i - 1]}, {t[i], poses[i], q[i], trig[i]}, 0);
  }
  // Output position of each input pose (its inserted poses go just before it), then filled on all threads.
  std::vector<size_t> at(static_cast<size_t>(n));
  size_t total = 0;
  for (int i = 0; i < n; ++i) {
    total += inserted[size_t(i)].size();
    at[size_t(i)] = total++;
    out.unresolved_blocks += unresolved[size_t(i)];
    out.inserted += int(inserted[size_t(i)].size());
  }
  out.poses.resize(total), out.t.resize(total), out.joints.resize(total), out.input_index.resize(total);
  std::vector<char> singular_out(total, 0);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    size_t j = at[size_t(i)] - inserted[size_t(i)].size();
    for (const Node& nd : inserted[size_t(i)]) {
      out.poses[j] = nd.pose;
      out.t[j] = nd.t;
      out.joints[j] = nd.q;
      out.input_index[j] = -1;
      singular_out[j] = near_singular(m, nd.pose.axis, cos_singular);
      ++j;
    }
    out.poses[j] = poses[size_t(i)];
    out.t[j] = t[size_t(i)];
    out.joints[j] = q[size_t(i)];
    out.input_index[j] = i;
    singular_out[j] = singular[size_t(i)];
  }
  for (size_t j = 0; j < total; ++j)
    if (singular_out[j]) out.singular.push_back(int(j));
  return out;
}

void require_reachable(const JointPath& path, const std::vector<ToolPose>& poses, const std::string& patch) {
  if (path.reachable) {
    // A joint that is not a number must never reach a program: the run stops here, naming the pose,
    // instead of posting it (a safeguard; the case seen on the HECC impeller, an unreachable branch
    // taken at the last pose, is fixed in solve_path).
    for (size_t j = 0; j < path.joints.size(); ++j) {
      const Joints& q = path.joints[j];
      if (q.linear.allFinite() && std::isfinite(q.rotary[0]) && std::isfinite(q.rotary[1])) continue;
      const ToolPose& at = path.poses.size() == path.joints.size() ? path.poses[j] : poses.at(std::min(j, poses.size() - 1));
      throw MachineError(fmt::format("patch '{}': block {} (tip {:.3f}, {:.3f}, {:.3f} mm): the kinematics gave a joint "
                                     "value that is not a finite number; nothing is posted",
                                     patch, j, at.tip.x(), at.tip.y(), at.tip.z()));
    }
    return;
  }
  const Eigen::Vector3d& tip = poses.at(size_t(path.failed_pose)).tip;
  throw MachineError(fmt::format("patch '{}': pose {} (tip {:.3f}, {:.3f}, {:.3f} mm) is out of reach: {}", patch,
                                 path.failed_pose, tip.x(), tip.y(), tip.z(), path.why));
}

Joints programmed(const Machine& m, const Joints& joints, const ToolPose& pose) {
  if (!m.controller.tcp && !m.controller.linuxcnc_trt) return joints;
  return {pose.tip, joints.rotary};
}

ToolPose programmed_pose(const Machine& m, const Joints& programmed, double tool_length_mm) {
  const ToolPose fk = forward(m, programmed, tool_length_mm);
  if (!m.controller.tcp && !m.controller.linuxcnc_trt) return fk;
  return {programmed.linear, fk.axis};
}

BlockTurn block_turn(const JointPath& path, size_t i) {
  const Eigen::Vector3d &a = path.poses[i - 1].axis, &b = path.poses[i].axis;
  return {std::abs(path.joints[i].rotary[0] - path.joints[i - 1].rotary[0]) +
              std::abs(path.joints[i].rotary[1] - path.joints[i - 1].rotary[1]),
          std::atan2(a.cross(b).norm(), a.dot(b)) * 180 / M_PI};
}

std::vector<SingularStretch> singular_stretches(const JointPath& path, double ratio, double min_rotary_deg) {
  std::vector<SingularStretch> out;
  SingularStretch cur;
  bool open = false;
  const auto close = [&] {
    if (open && cur.rotary_deg >= min_rotary_deg) out.push_back(cur);
    open = false;
  };
  for (size_t i = 1; i < path.joints.size(); ++i) {
    const auto [rot, turn] = block_turn(path, i);
    if (rot > 1e-6 && rot > ratio * turn) {
      if (!open) cur = {int(i) - 1, int(i), 0, 0}, open = true;
      cur.last_pose = int(i);
      cur.rotary_deg += rot;
      cur.axis_turn_deg += turn;
    } else {
      close();
    }
  }
  close();
  return out;
}

std::vector<BlockFeed> block_feeds(const Machine& m, const JointPath& path, double feed) {
  if (!(feed > 0)) throw InputError("feed: must be > 0 mm/min");
  return block_feeds(m, path, std::vector<double>(path.joints.size(), feed));
}

std::vector<BlockFeed> block_feeds(const Machine& m, const JointPath& path, const std::vector<double>& feed) {
  if (feed.size() != path.joints.size()) throw InputError("block_feeds: one feed per pose expected");
  std::vector<BlockFeed> out(path.joints.size());
  for (size_t i = 1; i < path.joints.size(); ++i) {
    if (!(feed[i] > 0)) throw InputError(fmt::format("feed: must be > 0 mm/min (block {})", i));
    const Joints &a = path.joints[i - 1], &b = path.joints[i];
    BlockFeed& bf = out[i];
    const double dist = (path.poses[i].tip - path.poses[i - 1].tip).norm();
    bf.minutes = dist / feed[i];
    for (int k = 0; k < 3; ++k) {
      const double need = std::abs(b.linear[k] - a.linear[k]) / m.linear[k].max_speed_mm_min;
      if (need > bf.minutes) bf.minutes = need, bf.limiting_axis = k;
    }
    for (int k = 0; k < 2; ++k) {
      const double need = std::abs(b.rotary[k] - a.rotary[k]) / m.rotary[k].max_speed_deg_min;
      if (need > bf.minutes) bf.minutes = need, bf.limiting_axis = 3 + k;
    }
    if (!(bf.minutes > 0)) bf.minutes = 1e-6;  // a zero-length block: keep F finite
    bf.inverse_time = 1 / bf.minutes;
    bf.tip_feed_mm_min = dist / bf.minutes;
  }
  return out;
}

}  // namespace flankcam
