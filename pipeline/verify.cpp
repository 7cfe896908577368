#include "pipeline/verify.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <sstream>

#include "core/atomic_file.h"
#include "core/check_surface.h"
#include "core/errors.h"
#include "core/file_probe.h"
#include "core/mesh.h"
#include "core/number_format.h"
#include "pipeline/post_stage.h"
#include "pipeline/run.h"
#include "postproc/report_html.h"
#include "postproc/report_svg.h"
#include "postproc/verify_view.h"
#include "postproc/viewer.h"

namespace flankcam::pipeline {

namespace {
namespace fs = std::filesystem;

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}


// The tool names a program's tool-change comments give: "T2 cone-2 D.. L.." -> {2: "cone-2"}.
std::map<int, std::string> tool_names(const std::string& text) {
  std::map<int, std::string> out;
  static const std::regex re(R"([(;]\s*T(\d+) (\S+) D[0-9.]+ L[0-9.]+)");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it)
    out.emplace(std::stoi((*it)[1].str()), (*it)[2].str());
  return out;
}

// The patches whose sections the program cuts, from its "patch NAME" comments, in order: one tool
// (shared or from the catalogue) cuts several patches and is named after the first.
std::vector<std::string> patch_names(const std::string& text) {
  std::vector<std::string> out;
  static const std::regex re(R"([(;]\s*patch ([A-Za-z0-9_.\-]+))");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it)
    if (std::find(out.begin(), out.end(), (*it)[1].str()) == out.end()) out.push_back((*it)[1].str());
  return out;
}

nlohmann::ordered_json round3(const Eigen::Vector3d& p) {
  return {std::round(p.x() * 1e4) / 1e4, std::round(p.y() * 1e4) / 1e4, std::round(p.z() * 1e4) / 1e4};
}
double r4(double x) { return std::isfinite(x) ? std::round(x * 1e4) / 1e4 : x; }

// verify.html's 3D view: every program's simulated motion in the work frame, where verify ran.
ViewerScene verify_page_view(const VerifyRun& run) {
  std::vector<VerifyViewProgram> programs;
  for (const VerifiedProgram& p : run.programs)
    programs.push_back({fs::path(p.file).filename().string(), &p.report, p.tools,
                        {"X", "Y", "Z", run.machine.rotary[0].name, run.machine.rotary[1].name}, !p.cl_data});
  return verify_view(run.design.mesh(), run.part_mm, run.options.gouge_tolerance_mm, programs, &run.machine);
}
}  // namespace

double VerifiedProgram::min_rapid_all_mm() const {
  return std::min({min_rapid_mm[0], min_rapid_mm[1], min_rapid_mm[2]});
}

int VerifyRun::failing() const {
  int n = 0;
  for (const VerifiedProgram& p : programs) n += !p.report.clean();
  return n;
}

std::vector<Eigen::Vector2d> read_meridian(const std::string& path) {
  std::istringstream in(read_text(path));
  std::vector<Eigen::Vector2d> out;
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#' || line.rfind("z_mm", 0) == 0) continue;
    const size_t comma = line.find(',');
    const std::optional<double> z = parse_number(line.substr(0, comma));
    std::optional<double> r;
    if (comma != std::string::npos) r = parse_number(line.substr(comma + 1));
    if (!z || !r) throw InputError(fmt::format("{}:{}: expected 'z_mm,r_mm'", path, n));
    out.emplace_back(*z, *r);
  }
  if (out.size() < 2) throw InputError(path + ": a tool meridian needs at least two rows z_mm,r_mm");
  return out;
}

VerifyRun verify(const VerifyRequest& request, const Progress& progress) {
  Job job = read_job(request.job);
  if (job.machine.empty()) throw InputError(job.file.string() + ": machine: missing (verify needs the machine)");
  Machine m = find_machine(job.machine, job.file.parent_path());
  ToolAssembly holder;
  holder.shank_length = job.holder.shank_length, holder.shank_diameter = job.holder.shank_diameter;
  holder.holder_length = job.holder.length, holder.holder_diameter = job.holder.diameter;
  holder.holder_diameter_far = job.holder.diameter_far, holder.holder_cylinder_length = job.holder.cylinder_length;
  std::map<int, std::vector<Eigen::Vector2d>> given;  // --tool T=FILE
  for (const std::string& t : request.tools) {
    const size_t eq = t.find('=');
    const auto n = eq == std::string::npos ? std::nullopt : parse_number(t.substr(0, eq));
    if (!n || *n < 0 || *n != std::floor(*n)) throw InputError("--tool " + t + ": expected T=FILE, e.g. 2=cone-2-tool.csv");
    given[int(*n)] = read_meridian(t.substr(eq + 1));
  }
  std::map<std::string, std::vector<std::string>> given_cl;  // --cl PROGRAM=FILE, by program
  for (const std::string& c : request.cl) {
    const size_t eq = c.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == c.size())
      throw InputError("--cl " + c + ": expected PROGRAM=FILE, e.g. cone-1.ngc=cone-1.apt");
    const std::string program = c.substr(0, eq);
    if (std::none_of(request.programs.begin(), request.programs.end(), [&](const std::string& p) { return p == program; }))
      throw InputError("--cl " + c + ": " + program + " is not one of the programs to verify");
    given_cl[program].push_back(c.substr(eq + 1));
  }
  // post.setup: auto: the rotation the run chose, from the first program's header (every program of a
  // run says its work frame).
  if (job.post.setup_auto && !request.programs.empty() && !is_cl_data_file(request.programs.front())) {
    static const std::regex frame(R"(work frame = part rotated X (\S+) Y (\S+) Z (\S+) deg)");
    const std::string text = read_text(request.programs.front());
    std::smatch mt;
    if (!std::regex_search(text, mt, frame))
      throw InputError(job.file.string() + ": post.setup: auto: " + request.programs.front() +
                       " does not say its work frame; give the rotation as post.setup.rotate");
    for (size_t k = 0; k < 3; ++k)
      if (const auto v = parse_number(mt[k + 1].str())) job.post.setup_rotate_deg[k] = *v;
  }
  // The part and the design surface on the machine (work frame), as the run checks its programs.
  const LoadedMesh surface = load_job_surface(job, progress);
  SurfaceIndex design(to_work(job.post, surface.mesh));
  std::optional<SurfaceIndex> separate;
  if (std::optional<LoadedMesh> part = load_job_part(job)) separate.emplace(to_work(job.post, std::move(part->mesh)));
  VerifyOptions vo;
  vo.gouge_tolerance_mm = job.tolerance_mm;
  // Rapids keep the job's clearance, as the run's own back-simulation holds the links it plans to it:
  // a rapid off the part but inside it is a finding (kind "clearance"), not a clean program.
  vo.link_clearance_mm = job.clearance_mm;
  vo.cl_tolerance_mm = job.post.tolerance_mm + VerifyOptions{}.cl_tolerance_mm - PostJob{}.tolerance_mm;
  vo.cl_angle_tolerance_deg = job.post.angle_tolerance_deg + VerifyOptions{}.cl_angle_tolerance_deg - PostJob{}.angle_tolerance_deg;
  VerifyRun run{std::move(job), std::move(m), vo, std::move(design), separate ? separate->mesh() : TriMesh{}, {}};
  const Job& j = run.job;
  const SurfaceIndex& part = separate ? *separate : run.design;
  // With a separate part the cut is judged as the run's back-simulation judges it: the part without
  // Φ's coarser twin by check_tolerance, Φ itself by the fitted tolerance.
  std::optional<SurfaceIndex> cut;
  VerifyOptions judge = run.options;
  if (separate) {
    const CheckPart cp = check_part(separate->mesh(), run.design, j.tolerance_mm);
    cut.emplace(cp.mesh);
    const CutJudgement c = cut_judgement(j, cp.twin_sag);
    judge.gouge_tolerance_mm = c.part_mm;
    judge.apart = c.apart(&*cut);
  }

  for (const std::string& file : request.programs) {
    const fs::path path(file);
    const std::string text = read_text(file);
    const auto tool_for = [&](int number, const std::string& name) {
      VerifyTool vt;
      vt.number = number;
      std::vector<Eigen::Vector2d> meridian;
      if (given.count(number)) meridian = given[number];
      else if (given.count(0)) meridian = given[0];
      else {
        const fs::path csv = path.parent_path() / (name + "-tool.csv");
        if (!is_file(csv))
          throw InputError(fmt::format("{}: tool T{}: no {} beside the program (give --tool {}=FILE)", file, number,
                                       csv.filename().string(), number));
        meridian = read_meridian(csv.string());
      }
      vt.assembly = assembly_from_meridian(meridian, holder);
      vt.length_mm = j.post.tool_length_mm > 0 ? j.post.tool_length_mm
                                               : j.holder.length + j.holder.cylinder_length + j.holder.shank_length +
                                                     vt.assembly.cutter_length();
      return vt;
    };
    VerifiedProgram r;
    r.file = file;
    if (is_cl_data_file(file)) {
      // CL-data is in part coordinates: placed on the machine like the part (post.setup).
      const ClProgram cl = to_work(j.post, parse_apt(text, file));
      VerifyTool vt;
      if (given.empty() && cl.profile.size() >= 2) {
        vt.assembly = assembly_from_meridian(cl.profile, holder);
      } else {
        vt = tool_for(cl.tool, path.stem().string());
      }
      r.meridian = vt.assembly.cutter;
      r.tools = {vt};
      r.cl_data = true;
      r.report = verify_cl(cl, part, vt, judge, &run.design);
    } else {
      std::vector<VerifyTool> tools;
      const std::map<int, std::string> names = tool_names(text);
      if (names.empty()) tools.push_back(tool_for(0, path.stem().string()));
      for (const auto& [number, name] : names) tools.push_back(tool_for(number, name));
      r.meridian = tools.front().assembly.cutter;
      r.tools = tools;
      // The CL-data the program was posted from (part coordinates, placed like the part).
      std::vector<ClReference> cl;
      const auto load_cl = [&](const std::string& apt, int tool) {
        ClReference ref{tool, to_work(j.post, read_apt(apt)), apt};
        r.cl_files.push_back(apt);
        cl.push_back(std::move(ref));
      };
      if (given_cl.count(file)) {
        const std::vector<std::string>& files = given_cl[file];
        for (const std::string& apt : files) load_cl(apt, 0);
        if (files.size() > 1)
          for (ClReference& ref : cl) ref.tool = ref.cl.tool;
      } else {
        std::vector<std::string> missing;
        const std::map<int, std::string> named = names.empty() ? std::map<int, std::string>{{0, path.stem().string()}} : names;
        for (const auto& [number, name] : named) {
          const fs::path apt = path.parent_path() / (name + ".apt");
          if (is_file(apt)) load_cl(apt.string(), number);
          else missing.push_back(apt.filename().string());
        }
        // Further patches of a tool named after another: their CL-data by the tool it loads.
        for (const std::string& name : patch_names(text)) {
          const fs::path apt = path.parent_path() / (name + ".apt");
          if (std::find(r.cl_files.begin(), r.cl_files.end(), apt.string()) != r.cl_files.end() ||
              std::find(missing.begin(), missing.end(), apt.filename().string()) != missing.end())
            continue;
          if (!is_file(apt)) {
            missing.push_back(apt.filename().string());
            continue;
          }
          load_cl(apt.string(), 0);
          cl.back().tool = cl.back().cl.tool;
        }
        if (!missing.empty())
          r.cl_note = fmt::format("no {} beside the program (or --cl {}=FILE): {} compared with CL-data",
                                  fmt::join(missing, ", "), file, cl.empty() ? "not" : "some tools' blocks not");
      }
      r.report = verify_text(text, dialect_of_file(file), file, run.machine, part, tools, judge, &run.design, cl);
    }
    r.min_rapid_mm = r.min_feed_mm = {INFINITY, INFINITY, INFINITY};
    for (const VerifiedBlock& b : r.report.blocks) {
      auto& mins = b.rapid ? r.min_rapid_mm : r.min_feed_mm;
      for (size_t k = 0; k < 3; ++k) mins[k] = std::min(mins[k], b.min_clearance_mm[k]);
    }
    progress(fmt::format("{}: {} motion blocks, {} hit(s)", file, r.report.blocks.size(), r.report.hits.size()));
    run.programs.push_back(std::move(r));
  }
  return run;
}

void write_verify(const VerifyRun& run, OutputDir& out) {
  const Job& job = run.job;
  const Machine& m = run.machine;
  const VerifyOptions& vo = run.options;
  nlohmann::ordered_json report;
  report["generator"] = "flankcam verify";
  report["job"] = job.file.string();
  report["machine"] = m.name;
  report["units"] = "mm";
  report["gouge_tolerance_mm"] = vo.gouge_tolerance_mm;
  report["rapid_clearance_mm"] = vo.link_clearance_mm;
  auto& programs = report["programs"] = nlohmann::ordered_json::array();
  HtmlReport html;
  html.title = "flankcam verify: " + job.file.filename().string();
  html.intro = {fmt::format("Back-simulation of each program from its text through {} ({}) against {} with the cutter "
                            "from its meridian, shank and holder from the job. Feed blocks may cut {} mm into the part "
                            "(the job's tolerance); rapids must keep {} mm from it (the job's clearance).",
                            m.name, m.kind(), job.part.filename().string(), vo.gouge_tolerance_mm, vo.link_clearance_mm)};
  html.columns = {"program", "verdict", "blocks", "min rapid clearance", "hits", "axis violations", "cycle min",
                  "coverage"};
  for (const VerifiedProgram& r : run.programs) {
    const VerifyReport& v = r.report;
    const std::array<double, 3>& rapid_min = r.min_rapid_mm;
    const std::array<double, 3>& feed_min = r.min_feed_mm;
    nlohmann::ordered_json blocks = nlohmann::ordered_json::array();
    for (const VerifiedBlock& b : v.blocks)
      blocks.push_back({b.line, b.tool_change ? "tool change" : b.rapid ? "rapid" : "feed", r4(b.min_clearance_mm[0]), r4(b.min_clearance_mm[1]),
                        r4(b.min_clearance_mm[2])});
    nlohmann::ordered_json hits = nlohmann::ordered_json::array();
    for (const VerifyHit& h : v.hits)
      hits.push_back({{"line", h.line}, {"block", h.block}, {"motion", h.tool_change ? "tool change" : h.rapid ? "rapid" : "feed"}, {"kind", h.kind()},
                      {"component", to_string(h.component)}, {"depth_mm", r4(h.depth_mm)}, {"point", round3(h.point)}});
    nlohmann::ordered_json viol = nlohmann::ordered_json::array();
    for (const AxisViolation& a : v.violations)
      viol.push_back({{"line", a.line}, {"axis", a.axis}, {"what", a.speed ? "speed" : "travel"}, {"value", r4(a.value)},
                      {"limit", r4(a.limit)}});
    const auto mins_json = [](const std::array<double, 3>& a) {
      return nlohmann::ordered_json{{"cutter", r4(a[0])}, {"shank", r4(a[1])}, {"holder", r4(a[2])}};
    };
    nlohmann::ordered_json e;
    e["file"] = r.file;
    e["clean"] = v.clean();
    if (!v.clean()) e["problem"] = v.first_problem(r.file);
    e["motion_blocks"] = v.blocks.size();
    e["positions_simulated"] = v.positions;
    e["min_clearance_rapid_mm"] = mins_json(rapid_min);
    e["min_clearance_feed_mm"] = mins_json(feed_min);
    e["collisions_and_gouges"] = hits;
    e["axis_violations"] = viol;
    nlohmann::ordered_json cl_json;
    cl_json["files"] = r.cl_files;
    if (!r.cl_note.empty()) cl_json["note"] = r.cl_note;
    cl_json["tolerance_mm"] = vo.cl_tolerance_mm;
    cl_json["angle_tolerance_deg"] = vo.cl_angle_tolerance_deg;
    cl_json["feed_blocks_compared"] = v.cl_blocks;
    cl_json["max_deviation_mm"] = r4(v.cl_max_deviation_mm);
    cl_json["max_angle_deg"] = r4(v.cl_max_angle_deg);
    nlohmann::ordered_json off = nlohmann::ordered_json::array();
    for (const ClDeviation& d : v.cl_deviations)
      off.push_back({{"line", d.line}, {"block", d.block}, {"deviation_mm", r4(d.deviation_mm)}, {"angle_deg", r4(d.angle_deg)},
                     {"tip", round3(d.tip)}});
    cl_json["off_cl_data"] = off;
    e["cl_data"] = cl_json;
    e["tool_changes_simulated"] = v.tool_changes;
    e["cycle_minutes"] = r4(v.cycle_minutes);
    e["cut_minutes"] = r4(v.cut_minutes);
    e["design_surface"] = {{"vertices_reached", v.design.reached}, {"within_tolerance", v.design.within},
                           {"coverage", r4(v.design.coverage())},
                           {"share_of_all_vertices", r4(v.design.share_of_all())}};
    e["blocks"] = {{"columns", {"line", "motion", "cutter_mm", "shank_mm", "holder_mm"}}, {"rows", blocks}};
    programs.push_back(e);

    const std::string verdict = v.clean() ? "clean" : fmt::format("{} hit(s)", v.hits.size());
    html.rows.push_back({fs::path(r.file).filename().string(), verdict, fmt::format("{}", v.blocks.size()),
                         fmt::format("{:.3f} mm", r.min_rapid_all_mm()), fmt::format("{}", v.hits.size()),
                         fmt::format("{}", v.violations.size()), fmt::format("{:.2f}", v.cycle_minutes),
                         fmt::format("{:.1f}%", 100 * v.design.coverage())});
    HtmlSection sec;
    sec.heading = fs::path(r.file).filename().string();
    for (const VerifyHit& h : v.hits)
      sec.warnings.push_back(fmt::format("line {}: {} at ({:.3f}, {:.3f}, {:.3f}) ({} block)", h.line,
                                         h.what(v.link_clearance_mm), h.point.x(), h.point.y(), h.point.z(),
                                         h.rapid ? "rapid" : "feed"));
    for (const AxisViolation& a : v.violations)
      sec.warnings.push_back(fmt::format("line {}: {} {} {:.4f} beyond {:.4f}", a.line, a.axis,
                                         a.speed ? "speed" : "travel", a.value, a.limit));
    sec.facts = {{"motion blocks", fmt::format("{}", v.blocks.size())},
                 {"positions simulated", fmt::format("{}", v.positions)},
                 {"min clearance in rapids (cutter, shank, holder)",
                  fmt::format("{:.3f}, {:.3f}, {:.3f} mm", rapid_min[0], rapid_min[1], rapid_min[2])},
                 {"min clearance in feed blocks (cutter, shank, holder)",
                  fmt::format("{:.3f}, {:.3f}, {:.3f} mm", feed_min[0], feed_min[1], feed_min[2])},
                 {"cycle time", fmt::format("{:.2f} min ({:.2f} min cutting)", v.cycle_minutes, v.cut_minutes)},
                 {"design surface within tolerance", fmt::format("{:.1f}% of {} vertices reached", 100 * v.design.coverage(),
                                                                 v.design.reached)}};
    std::vector<SvgHitMarker> markers;
    for (const VerifyHit& h : v.hits)
      markers.push_back({h.point,
                         h.kind() == "clearance" ? fmt::format("L{} {} {:.2f} off", h.line, to_string(h.component), -h.depth_mm)
                                                 : fmt::format("L{} {} {:.2f}", h.line, to_string(h.component), h.depth_mm),
                         h.kind() == "gouge"});
    sec.svgs.push_back(deviation_map_svg(run.design.mesh(), v.design.deviation_mm, vo.gouge_tolerance_mm, {}, r.meridian,
                                         fmt::format("{}: machined deviation of the design surface, hits marked",
                                                     fs::path(r.file).filename().string()),
                                         160, markers));
    html.sections.push_back(std::move(sec));
  }
  html.viewer = viewer_html(verify_page_view(run));
  write_file_atomically(out.file("verify.json"), [&](std::ostream& o) { o << report.dump(1) << "\n"; });
  write_file_atomically(out.file("verify.html"), [&](std::ostream& o) { o << report_html(html); });
  out.commit();
}

}  // namespace flankcam::pipeline
