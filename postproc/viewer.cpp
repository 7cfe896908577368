#include "postproc/viewer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>

#include "core/errors.h"
#include "postproc/markup.h"
#include "postproc/viewer_assets.h"

namespace flankcam {

DeviationBand deviation_band(double dev_mm, double tol_mm) {
  if (!std::isfinite(dev_mm)) return DeviationBand::None;
  if (std::abs(dev_mm) <= tol_mm) return DeviationBand::Within;
  return dev_mm > 0 ? DeviationBand::Under : DeviationBand::Over;
}

bool viewer_available() { return !viewer_three_js().empty(); }

std::string ViewerScene::validate() const {
  if (!(tolerance_mm > 0)) return "tolerance_mm: must be > 0";
  if (surface_mm.faces.empty()) return "surface: no triangles";
  const auto mesh_ok = [](const TriMesh& m) {
    for (const auto& f : m.faces)
      for (int i : f)
        if (i < 0 || size_t(i) >= m.vertices.size()) return false;
    return true;
  };
  if (!mesh_ok(surface_mm)) return "surface: face index out of range";
  if (!mesh_ok(part_mm)) return "part: face index out of range";
  for (const ViewerPatch& p : patches) {
    if (!p.design_deviation_mm.empty() && p.design_deviation_mm.size() != surface_mm.vertices.size())
      return fmt::format("patch '{}': {} deviations for {} surface vertices", p.name, p.design_deviation_mm.size(),
                         surface_mm.vertices.size());
    if (p.meridian.size() < 2) return fmt::format("patch '{}': meridian needs two points", p.name);
    if (!mesh_ok(p.envelope_mm)) return fmt::format("patch '{}': envelope face index out of range", p.name);
    for (const ViewerMarker& m : p.markers) {
      if (m.frames.empty() && (m.pose < 0 || size_t(m.pose) >= p.poses.size()))
        return fmt::format("patch '{}': marker pose {} of {}", p.name, m.pose, p.poses.size());
      if (!m.frames.empty() && m.frames.size() != tracks.size())
        return fmt::format("patch '{}': marker '{}' has frames for {} of {} tracks", p.name, m.label, m.frames.size(),
                           tracks.size());
      for (size_t t = 0; t < m.frames.size(); ++t)
        if (m.frames[t] < -1 || (m.frames[t] >= 0 && size_t(m.frames[t]) >= tracks[t].frames.size()))
          return fmt::format("patch '{}': marker '{}' frame {} of {} in track '{}'", p.name, m.label, m.frames[t],
                             tracks[t].frames.size(), tracks[t].name);
    }
  }
  if (machine && machine->tool_length_mm.size() != patches.size())
    return fmt::format("machine: {} tool lengths for {} patches", machine->tool_length_mm.size(), patches.size());
  for (const ViewerColouring& c : colourings)
    if (c.deviation_mm.size() != surface_mm.vertices.size())
      return fmt::format("colouring '{}': {} deviations for {} surface vertices", c.name, c.deviation_mm.size(),
                         surface_mm.vertices.size());
  for (const ViewerTrack& t : tracks)
    for (const ViewerFrame& f : t.frames)
      if (f.patch < 0 || size_t(f.patch) >= patches.size())
        return fmt::format("track '{}': patch {} of {}", t.name, f.patch, patches.size());
  return {};
}

std::string ViewerOptions::validate() const {
  if (max_surface_triangles < 100) return "max_surface_triangles: must be >= 100";
  if (max_part_triangles < 100) return "max_part_triangles: must be >= 100";
  if (max_envelope_triangles < 100) return "max_envelope_triangles: must be >= 100";
  if (max_frames < 2) return "max_frames: must be >= 2";
  if (max_total_frames < 2) return "max_total_frames: must be >= 2";
  return {};
}

ViewerTrack viewer_track(const Posted& posted, const std::string& name, const std::array<std::string, 2>& rotary_names,
                         const Eigen::Matrix3d& R_part_work, const Eigen::Vector3d& t_part_work,
                         const std::vector<std::string>& patch_names) {
  ViewerTrack t;
  t.name = name;
  t.axis_names = {"X", "Y", "Z", rotary_names[0], rotary_names[1]};
  const auto patch_of = [&](const std::string& n) {
    const auto it = std::find(patch_names.begin(), patch_names.end(), n);
    return it == patch_names.end() ? 0 : int(it - patch_names.begin());
  };
  int patch = posted.sections.empty() ? 0 : patch_of(posted.sections.front().patch);
  const auto& blocks = posted.program.blocks;
  for (size_t b = 0; b < blocks.size(); ++b) {
    for (const PostedSection& s : posted.sections)
      if (int(b) >= s.first_block && int(b) < s.end_block) patch = patch_of(s.patch);
    const auto* m = std::get_if<NcMove>(&blocks[b]);
    if (!m) continue;
    ViewerFrame f;
    f.pose = {R_part_work * m->pose.tip + t_part_work, (R_part_work * m->pose.axis).normalized()};
    f.values = {m->at.linear.x(), m->at.linear.y(), m->at.linear.z(), m->at.rotary[0], m->at.rotary[1]};
    f.rapid = m->rapid;
    f.patch = patch;
    t.frames.push_back(f);
  }
  return t;
}

Decimated decimate(const TriMesh& mesh, int max_triangles) {
  Decimated d;
  if (mesh.faces.size() <= size_t(std::max(max_triangles, 0)) || mesh.vertices.empty()) {
    d.mesh = mesh;
    d.vertex_map.resize(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) d.vertex_map[i] = int(i);
    return d;
  }
  Eigen::Vector3d lo = mesh.vertices.front(), hi = lo;
  for (const auto& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  double area = 0;
  for (const auto& f : mesh.faces)
    area += 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).norm();
  // About two triangles per occupied cell of a surface: start a little below the budget's cell.
  double h = std::max(std::sqrt(2 * area / max_triangles) * 0.8, 1e-9 * std::max((hi - lo).norm(), 1.0));
  for (;;) {
    std::map<std::array<long long, 3>, int> cell_index;
    std::vector<Eigen::Vector3d> sum;
    std::vector<int> count;
    d.vertex_map.assign(mesh.vertices.size(), -1);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const Eigen::Vector3d c = (mesh.vertices[i] - lo) / h;
      const std::array<long long, 3> key{(long long)std::floor(c.x()), (long long)std::floor(c.y()), (long long)std::floor(c.z())};
      const auto [it, added] = cell_index.emplace(key, int(sum.size()));
      if (added) sum.emplace_back(Eigen::Vector3d::Zero()), count.push_back(0);
      sum[it->second] += mesh.vertices[i];
      ++count[it->second];
      d.vertex_map[i] = it->second;
    }
    d.mesh.vertices.resize(sum.size());
    for (size_t k = 0; k < sum.size(); ++k) d.mesh.vertices[k] = sum[k] / count[k];
    d.mesh.faces.clear();
    std::set<std::array<int, 3>> seen;
    for (const auto& f : mesh.faces) {
      const std::array<int, 3> g{d.vertex_map[f[0]], d.vertex_map[f[1]], d.vertex_map[f[2]]};
      if (g[0] == g[1] || g[1] == g[2] || g[0] == g[2]) continue;
      std::array<int, 3> key = g;
      std::sort(key.begin(), key.end());
      if (seen.insert(key).second) d.mesh.faces.push_back(g);
    }
    if (d.mesh.faces.size() <= size_t(max_triangles)) return d;
    h *= 1.25;
  }
}

namespace {

std::string base64(const std::vector<std::uint8_t>& bytes) {
  static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string s;
  s.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const unsigned n = bytes.size() - i;
    const std::uint32_t v = std::uint32_t(bytes[i]) << 16 | (n > 1 ? std::uint32_t(bytes[i + 1]) << 8 : 0) | (n > 2 ? bytes[i + 2] : 0);
    s += abc[v >> 18 & 63];
    s += abc[v >> 12 & 63];
    s += n > 1 ? abc[v >> 6 & 63] : '=';
    s += n > 2 ? abc[v & 63] : '=';
  }
  return s;
}

// Little-endian bytes whatever the host, so the page is the same everywhere.
void put_u32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) b.push_back(std::uint8_t(v >> (8 * k)));
}
void put_f32(std::vector<std::uint8_t>& b, double x) {
  const float f = float(x);
  std::uint32_t v;
  static_assert(sizeof v == sizeof f);
  std::memcpy(&v, &f, sizeof v);
  put_u32(b, v);
}
std::string f32(const std::vector<double>& xs) {
  std::vector<std::uint8_t> b;
  b.reserve(xs.size() * 4);
  for (double x : xs) put_f32(b, x);
  return base64(b);
}

// JSON string; '<' escaped so the data can never close its <script>.
std::string jstr(const std::string& s) {
  std::string o = "\"";
  for (unsigned char c : s) {
    if (c == '"') o += "\\\"";
    else if (c == '\\') o += "\\\\";
    else if (c == '<') o += "\\u003c";
    else if (c < 0x20) o += fmt::format("\\u{:04x}", c);
    else o += char(c);
  }
  return o + "\"";
}
std::string json_num(double x) {
  std::string s = fmt::format("{:.6f}", std::abs(x) < 5e-7 ? 0.0 : x);
  return s;
}

std::string mesh_json(const TriMesh& m, size_t original_triangles) {
  std::vector<double> pos;
  pos.reserve(m.vertices.size() * 3);
  for (const auto& v : m.vertices) pos.insert(pos.end(), {v.x(), v.y(), v.z()});
  std::vector<std::uint8_t> idx;
  idx.reserve(m.faces.size() * 12);
  for (const auto& f : m.faces)
    for (int i : f) put_u32(idx, std::uint32_t(i));
  return fmt::format(R"({{"vertices":{},"triangles":{},"original_triangles":{},"positions":"{}","indices":"{}"}})",
                     m.vertices.size(), m.faces.size(), original_triangles, f32(pos), base64(idx));
}

// Per output vertex: the member deviation of largest magnitude (a small gouge stays visible).
std::vector<double> merge_deviation(const std::vector<double>& dev, const std::vector<int>& vertex_map, size_t n) {
  std::vector<double> out(n, std::nan(""));
  for (size_t i = 0; i < dev.size(); ++i) {
    double& o = out[size_t(vertex_map[i])];
    if (std::isfinite(dev[i]) && !(std::abs(o) >= std::abs(dev[i]))) o = dev[i];
  }
  return out;
}

std::string bands_b64(const std::vector<double>& dev, double tol) {
  if (dev.empty()) return {};
  std::vector<std::uint8_t> b;
  b.reserve(dev.size());
  for (double x : dev) b.push_back(std::uint8_t(deviation_band(x, tol)));
  return base64(b);
}

std::string meridian_json(const std::vector<Eigen::Vector2d>& zr) {
  std::string s = "[";
  for (size_t i = 0; i < zr.size(); ++i) s += fmt::format("{}[{},{}]", i ? "," : "", json_num(zr[i].x()), json_num(zr[i].y()));
  return s + "]";
}

// Tracks subsampled to `max_frames`, both ends and the frames markers jump to (`must`) kept. Sorted.
std::vector<size_t> kept_frames(size_t n, int max_frames, const std::set<size_t>& must) {
  std::vector<size_t> k;
  if (n <= size_t(max_frames)) {
    for (size_t i = 0; i < n; ++i) k.push_back(i);
    return k;
  }
  std::set<size_t> all = must;
  for (int i = 0; i < max_frames; ++i) all.insert(size_t(std::llround(double(i) * double(n - 1) / (max_frames - 1))));
  return {all.begin(), all.end()};
}

std::string vec_json(const Eigen::Vector3d& v) { return fmt::format("[{},{},{}]", json_num(v.x()), json_num(v.y()), json_num(v.z())); }

// The chain as kinematics/kinematics.cpp applies it: rotary[0] outermost, tables about points in
// part coordinates, heads about points relative to the head pivot (gauge length above the nose).
std::string machine_json(const ViewerMachine& vm) {
  const Machine& m = vm.machine;
  std::string j = fmt::format(R"({{"name":{},"kind":{},"rotary":[)", jstr(m.name), jstr(m.kind()));
  for (size_t k = 0; k < 2; ++k) {
    const RotaryAxis& a = m.rotary[k];
    j += fmt::format(R"({}{{"name":{},"table":{},"direction":{},"pivot":{}}})", k ? "," : "", jstr(a.name),
                     a.carries == Carrier::Table ? "true" : "false", vec_json(a.direction), vec_json(a.pivot));
  }
  j += fmt::format(R"(],"spindle":{},"gauge_length_mm":{},"tool_length_mm":[)", vec_json(m.spindle_direction),
                   json_num(m.gauge_length_mm));
  for (size_t k = 0; k < vm.tool_length_mm.size(); ++k) j += (k ? "," : "") + json_num(vm.tool_length_mm[k]);
  return j + "]}";
}

std::string check(const ViewerScene& scene, const ViewerOptions& options) {
  if (std::string e = options.validate(); !e.empty()) return "viewer options: " + e;
  if (std::string e = scene.validate(); !e.empty()) return "viewer scene: " + e;
  return {};
}

}  // namespace

std::string viewer_json(const ViewerScene& scene, const ViewerOptions& options) {
  if (std::string e = check(scene, options); !e.empty()) throw InputError(e);
  const double tol = scene.tolerance_mm;
  const Decimated surface = decimate(scene.surface_mm, options.max_surface_triangles);
  const size_t nv = surface.mesh.vertices.size();

  std::string j = fmt::format(R"({{"format":"flankcam-viewer 1","units":"mm","tolerance_mm":{},)", json_num(tol));
  j += "\n\"surface\":" + mesh_json(surface.mesh, scene.surface_mm.faces.size());
  // Φ after all patches (programs): each removes material up to its envelope, the smallest deviation stays.
  std::vector<double> all(scene.surface_mm.vertices.size(), std::nan(""));
  const auto combine = [&](const std::vector<double>& dev) {
    for (size_t i = 0; i < dev.size(); ++i)
      if (std::isfinite(dev[i]) && !(all[i] <= dev[i])) all[i] = dev[i];
  };
  for (const ViewerPatch& p : scene.patches) combine(p.design_deviation_mm);
  for (const ViewerColouring& c : scene.colourings) combine(c.deviation_mm);
  j += ",\n\"combined\":" + jstr(scene.combined_name);
  j += ",\n\"bands\":\"" + bands_b64(merge_deviation(all, surface.vertex_map, nv), tol) + "\"";
  j += ",\n\"colourings\":[";
  for (size_t k = 0; k < scene.colourings.size(); ++k)
    j += fmt::format("{}{{\"name\":{},\"bands\":\"{}\"}}", k ? "," : "", jstr(scene.colourings[k].name),
                     bands_b64(merge_deviation(scene.colourings[k].deviation_mm, surface.vertex_map, nv), tol));
  j += "]";
  j += ",\n\"machine\":" + (scene.machine ? machine_json(*scene.machine) : std::string("null"));
  j += ",\n\"part\":";
  j += scene.part_mm.faces.empty() ? "null"
                                   : mesh_json(decimate(scene.part_mm, options.max_part_triangles).mesh, scene.part_mm.faces.size());

  // Tracks first (the markers point into them), each subsampled the same way it is written.
  std::vector<std::set<size_t>> must(scene.tracks.size());
  for (const ViewerPatch& p : scene.patches)
    for (const ViewerMarker& m : p.markers)
      for (size_t t = 0; t < m.frames.size(); ++t)
        if (m.frames[t] >= 0) must[t].insert(size_t(m.frames[t]));
  size_t total = 0;
  for (const ViewerTrack& t : scene.tracks) total += t.frames.size();
  std::vector<std::vector<size_t>> kept;
  for (size_t t = 0; t < scene.tracks.size(); ++t) {
    const size_t n = scene.tracks[t].frames.size();
    const double share = total > size_t(options.max_total_frames) ? double(n) * options.max_total_frames / double(total) : double(n);
    kept.push_back(kept_frames(n, std::max(2, std::min(options.max_frames, int(share))), must[t]));
  }

  j += ",\n\"patches\":[";
  for (size_t k = 0; k < scene.patches.size(); ++k) {
    const ViewerPatch& p = scene.patches[k];
    const ToolAssembly& a = p.assembly;
    const double L = p.meridian.back().x();
    std::vector<Eigen::Vector2d> shank, holder;
    if (a.shank_length > 0) shank = {{L, 0.5 * a.shank_diameter}, {L + a.shank_length, 0.5 * a.shank_diameter}};
    if (a.holder_length > 0) {
      const double z0 = L + a.shank_length;
      holder = {{z0, 0.5 * a.holder_diameter}, {z0 + a.holder_length, 0.5 * a.holder_diameter_far}};
      if (a.holder_cylinder_length > 0)
        holder.emplace_back(z0 + a.holder_length + a.holder_cylinder_length, 0.5 * a.holder_diameter_far);
    }
    // The axis ruled surface: tip (rail a) to the cutter's end (rail b) at every fitted pose.
    std::vector<double> rails;
    for (const ToolPose& q : p.poses) {
      const Eigen::Vector3d b = q.tip + L * q.axis;
      rails.insert(rails.end(), {q.tip.x(), q.tip.y(), q.tip.z(), b.x(), b.y(), b.z()});
    }
    const std::string bands = p.design_deviation_mm.empty()
                                  ? std::string("null")
                                  : "\"" + bands_b64(merge_deviation(p.design_deviation_mm, surface.vertex_map, nv), tol) + "\"";
    j += fmt::format("{}\n{{\"name\":{},\"cutter\":{},\"shank\":{},\"holder\":{},\"bands\":{},\"poses\":{},\"rails\":\"{}\",",
                     k ? "," : "", jstr(p.name), meridian_json(p.meridian), meridian_json(shank), meridian_json(holder),
                     bands, p.poses.size(), f32(rails));
    j += "\"envelope\":" +
         (p.envelope_mm.faces.empty() ? std::string("null")
                                      : mesh_json(decimate(p.envelope_mm, options.max_envelope_triangles).mesh, p.envelope_mm.faces.size()));
    j += ",\"markers\":[";
    for (size_t m = 0; m < p.markers.size(); ++m) {
      const ViewerMarker& mk = p.markers[m];
      // Where the marker jumps: per track, its frame as kept, or the frame of this patch nearest
      // the worst pose (-1: none).
      std::string frames;
      for (size_t t = 0; t < scene.tracks.size(); ++t) {
        if (!mk.frames.empty()) {
          const auto it = std::lower_bound(kept[t].begin(), kept[t].end(), size_t(std::max(mk.frames[t], 0)));
          frames += fmt::format("{}{}", t ? "," : "", mk.frames[t] < 0 ? -1 : int(it - kept[t].begin()));
          continue;
        }
        const ToolPose& worst = p.poses[size_t(mk.pose)];
        int best = -1;
        double best_d = 1e300;
        for (size_t i = 0; i < kept[t].size(); ++i) {
          const ViewerFrame& f = scene.tracks[t].frames[kept[t][i]];
          if (f.patch != int(k)) continue;
          const double dist = (f.pose.tip - worst.tip).norm() + (f.pose.axis - worst.axis).norm();
          if (dist < best_d) best_d = dist, best = int(i);
        }
        frames += fmt::format("{}{}", t ? "," : "", best);
      }
      j += fmt::format(R"({}{{"at":[{},{},{}],"pose":{},"label":{},"frames":[{}]}})", m ? "," : "", json_num(mk.at_mm.x()),
                       json_num(mk.at_mm.y()), json_num(mk.at_mm.z()), mk.pose, jstr(mk.label), frames);
    }
    j += "]}";
  }
  j += "],\n\"tracks\":[";
  for (size_t t = 0; t < scene.tracks.size(); ++t) {
    const ViewerTrack& tr = scene.tracks[t];
    std::vector<double> tip, axis, values;
    std::vector<std::uint8_t> rapid, patch, line;
    for (size_t i : kept[t]) {
      const ViewerFrame& f = tr.frames[i];
      tip.insert(tip.end(), {f.pose.tip.x(), f.pose.tip.y(), f.pose.tip.z()});
      axis.insert(axis.end(), {f.pose.axis.x(), f.pose.axis.y(), f.pose.axis.z()});
      values.insert(values.end(), f.values.begin(), f.values.end());
      rapid.push_back(f.rapid);
      put_u32(patch, std::uint32_t(f.patch));
      put_u32(line, std::uint32_t(std::max(f.line, 0)));
    }
    std::string names;
    for (size_t a = 0; a < 5; ++a) names += (a ? "," : "") + jstr(tr.axis_names[a]);
    j += fmt::format(
        "{}\n{{\"name\":{},\"axes\":[{}],\"has_values\":{},\"frames\":{},\"original_frames\":{},\"tip\":\"{}\",\"axis\":\"{}\","
        "\"values\":\"{}\",\"rapid\":\"{}\",\"patch\":\"{}\",\"line\":\"{}\"}}",
        t ? "," : "", jstr(tr.name), names, tr.has_values ? "true" : "false", kept[t].size(), tr.frames.size(), f32(tip),
        f32(axis), f32(values), base64(rapid), base64(patch), base64(line));
  }
  return j + "]}\n";
}

std::string viewer_html(const ViewerScene& scene, const ViewerOptions& options) {
  const std::string data = viewer_json(scene, options);
  const std::string tol = fmt::format("{}", scene.tolerance_mm);
  // Legend entries and switches only for what the scene has (verify.html: no Ω, no fitted poses).
  const bool envelopes = std::any_of(scene.patches.begin(), scene.patches.end(), [](const ViewerPatch& p) { return !p.envelope_mm.faces.empty(); });
  const bool ruled = std::any_of(scene.patches.begin(), scene.patches.end(), [](const ViewerPatch& p) { return p.poses.size() >= 2; });
  std::string h =
      "<section id=\"flankcam-view\">\n<style>\n"
      "#fcv-canvas{width:100%;height:640px;display:block;border:1px solid #bbb;background:#f4f6f9}\n"
      ".fcv-wrap{position:relative}\n"
      ".fcv-legend{position:absolute;top:8px;right:8px;background:rgba(255,255,255,.88);padding:6px 10px;font-size:13px;"
      "border:1px solid #ccc}\n"
      ".fcv-legend i{display:inline-block;width:12px;height:12px;margin-right:6px;vertical-align:middle}\n"
      ".fcv-controls{margin:8px 0;line-height:2}\n#fcv-slider{width:45%;vertical-align:middle}\n"
      "#fcv-readout{font-family:monospace;margin:4px 0}\n#fcv-markers button{margin:2px 6px 2px 0;cursor:pointer}\n"
      "body.fcv-only{margin:0;max-width:none}\nbody.fcv-only>*:not(#flankcam-view){display:none}\n"
      "body.fcv-only #flankcam-view{border:0;margin:0}\n"
      "body.fcv-only #flankcam-view>h2,body.fcv-only #flankcam-view>p{display:none}\n"
      "</style>\n<h2>3D view</h2>\n"
      "<p>Drag to turn, wheel to zoom, right-drag (or shift-drag) to pan. The slider and Play step through the poses of "
      "the chosen program; its programmed axis values are shown below. Lengths in mm, angles in degrees.</p>\n"
      "<div class=\"fcv-wrap\"><canvas id=\"fcv-canvas\"></canvas>\n<div class=\"fcv-legend\">"
      "<div><i style=\"background:#3caa50\"></i>within &#177;" + markup_escape(tol) + " mm</div>"
      "<div><i style=\"background:#d72828\"></i>undercut &gt; " + markup_escape(tol) + " mm (material left)</div>"
      "<div><i style=\"background:#2850d7\"></i>overcut &lt; &#8722;" + markup_escape(tol) + " mm</div>"
      "<div><i style=\"background:#aaaaaa\"></i>not reached</div>" +
      std::string(envelopes ? "<div><i style=\"background:#d8b840\"></i>machined envelope &#937;</div>" : "") +
      std::string(ruled ? "<div><i style=\"background:#9a5cd0\"></i>axis ruled surface</div>" : "") +
      "<div><i style=\"background:#ff2060;border-radius:50%\"></i>collision / gouge</div></div></div>\n"
      "<div class=\"fcv-controls\"><label>program <select id=\"fcv-track\"></select></label>"
      " <label>colour by <select id=\"fcv-colour\"></select></label>"
      " <button id=\"fcv-play\" type=\"button\">Play</button>"
      " <input id=\"fcv-slider\" type=\"range\" min=\"0\" max=\"0\" value=\"0\" step=\"1\">"
      " <span id=\"fcv-frame\"></span><br>" +
      std::string(envelopes ? "<label><input type=\"checkbox\" id=\"fcv-show-envelope\" checked> envelopes</label> " : "") +
      std::string(ruled ? "<label><input type=\"checkbox\" id=\"fcv-show-ruled\" checked> ruled surfaces</label> " : "") +
      "<label><input type=\"checkbox\" id=\"fcv-show-path\" checked> tool path</label>"
      " <label><input type=\"checkbox\" id=\"fcv-show-part\" checked> part</label>"
      " <label><input type=\"checkbox\" id=\"fcv-show-tool\" checked> tool</label>" +
      std::string(scene.machine ? " <label><input type=\"checkbox\" id=\"fcv-machine\"> machine moving (tables turn, "
                                  "heads tilt)</label>"
                                : "") +
      "</div>\n"
      "<div id=\"fcv-readout\"></div>\n<div id=\"fcv-markers\"></div>\n";
  if (!viewer_available()) {
    return h +
           "<p class=\"warn\">This flankcam was built without three.js (Debian package libjs-three): no 3D view.</p>\n"
           "<script>document.body.setAttribute('data-flankcam-viewer','error: three.js was not available when flankcam "
           "was built');</script>\n</section>\n";
  }
  h += "<script type=\"application/json\" id=\"fcv-data\">" + data + "</script>\n";
  // The error hooks go first: three.js and the view report through them.
  for (const std::string_view js : {viewer_guard_js(), viewer_three_js(), viewer_orbit_js(), viewer_page_js()})
    h.append("<script>\n").append(js).append("\n</script>\n");
  h += "</section>\n";
  return h;
}

}  // namespace flankcam
