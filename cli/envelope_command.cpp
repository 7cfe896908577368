// `flankcam envelope`: exact envelopes of analytic tool motions (ground truth).
#include <fmt/format.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "core/atomic_file.h"
#include "pipeline/output_dir.h"
#include "core/envelope.h"
#include "core/errors.h"

namespace flankcam::cli {

namespace {
struct EnvelopeArgs {
  std::string profile = "cone", out;
  AnalyticMotionOptions motion;
  double radius = 6.0, radius_end = 9.0, bulge = 1.5;
  std::vector<double> spline = {5.0, 6.5, 7.5, 6.5, 7.0, 8.5};
  int grid_s = 66, grid_t = 200, sheet = 1;
};

RadiusProfile make_profile(const EnvelopeArgs& a) {
  if (a.profile == "cylinder") return cylinder_profile(a.radius);
  if (a.profile == "cone") return cone_profile(a.radius, a.radius_end);
  if (a.profile == "barrel") return barrel_profile(a.radius, a.bulge);
  if (a.profile == "spline") return spline_profile(a.spline);
  throw InputError("--profile: unknown profile '" + a.profile + "' (cylinder, cone, barrel, spline)");
}

int run_envelope(const EnvelopeArgs& args) {
  const RadiusProfile profile = make_profile(args);
  for (int j = 0; j < 200; ++j)
    if (!(profile.d(j / 199.0) > 0)) throw InputError("--radius: the tool radius must stay positive along the axis");
  if (args.sheet != 1 && args.sheet != -1) throw InputError("--sheet: must be 1 or -1");
  const LineMotion motion = analytic_motion(args.motion);
  const EnvelopeGrid grid = envelope_grid(motion, profile, args.grid_s, args.grid_t, args.sheet);
  if (grid.invalid_points > 0)
    throw InputError(fmt::format("the envelope does not exist at {} grid points: the profile is too steep "
                                 "for this motion (lower --radius-end/--bulge)", grid.invalid_points));

  pipeline::OutputDir out(args.out);
  const std::string obj = args.out + "/envelope.obj", truth = args.out + "/truth.json";
  nlohmann::ordered_json j;
  j["generator"] = "flankcam envelope";
  j["units"] = "mm";
  j["profile"] = {{"kind", args.profile}, {"control", std::vector<double>(profile.radius.ctrl.data(),
                                                                            profile.radius.ctrl.data() + profile.radius.ctrl.size())}};
  j["motion"] = {{"kind", args.motion.kind}, {"travel", args.motion.travel}, {"twist_deg", args.motion.twist_deg}};
  j["sheet"] = args.sheet;
  j["length"] = args.motion.length;
  j["grid"] = {{"s", args.grid_s}, {"t", args.grid_t}};
  j["folded_triangles"] = grid.folded_triangles;
  auto& axis = j["axis"] = nlohmann::ordered_json::array();
  auto& ts = j["t"] = nlohmann::ordered_json::array();
  for (int i = 0; i < args.grid_t; ++i) {
    const double t = double(i) / (args.grid_t - 1);
    const Eigen::Vector3d a = motion.a(t), b = motion.b(t);
    ts.push_back(t);
    axis.push_back({a.x(), a.y(), a.z(), b.x(), b.y(), b.z()});
  }
  auto& radius = j["radius"] = nlohmann::ordered_json::array();
  for (int k = 0; k < args.grid_s; ++k) radius.push_back(profile.d(double(k) / (args.grid_s - 1)));

  write_obj(out.file("envelope.obj"), grid.mesh,
            fmt::format("exact envelope, profile {}, motion {}, L {} mm", args.profile, args.motion.kind, args.motion.length));
  write_file_atomically(out.file("truth.json"), [&](std::ostream& o) { o << j.dump(1) << '\n'; });
  out.commit();
  fmt::print("wrote {} ({} vertices, {} triangles, {} folded) and {}\n", obj, grid.mesh.vertices.size(),
             grid.mesh.faces.size(), grid.folded_triangles, truth);
  return 0;
}
}  // namespace

Run add_envelope_command(CLI::App& app) {
  auto args = std::make_shared<EnvelopeArgs>();
  CLI::App* cmd = app.add_subcommand("envelope", "write the exact envelope of an analytic tool motion (ground truth)");
  cmd->add_option("--profile", args->profile, "tool profile: cylinder | cone | barrel | spline")->capture_default_str();
  cmd->add_option("--motion", args->motion.kind, "axis motion: twist | arc | helix | s-curve")->capture_default_str();
  cmd->add_option("--out", args->out, "output directory (envelope.obj, truth.json)")->required();
  cmd->add_option("--length", args->motion.length, "axis segment length L, mm")->capture_default_str();
  cmd->add_option("--travel", args->motion.travel, "path size, mm")->capture_default_str();
  cmd->add_option("--twist", args->motion.twist_deg, "axis rotation over the motion, degrees")->capture_default_str();
  cmd->add_option("--radius", args->radius, "radius at the tip (s = 0), mm")->capture_default_str();
  cmd->add_option("--radius-end", args->radius_end, "cone: radius at s = 1, mm")->capture_default_str();
  cmd->add_option("--bulge", args->bulge, "barrel: extra radius at mid-length, mm")->capture_default_str();
  cmd->add_option("--spline", args->spline, "spline: control radii, mm (>= 4)")->capture_default_str();
  cmd->add_option("--grid-s", args->grid_s, "samples along the axis")->capture_default_str()->check(CLI::Range(2, 100000));
  cmd->add_option("--grid-t", args->grid_t, "samples along the motion")->capture_default_str()->check(CLI::Range(2, 1000000));
  cmd->add_option("--sheet", args->sheet, "envelope sheet: 1 or -1")->capture_default_str();
  return [args] { return run_envelope(*args); };
}

}  // namespace flankcam::cli
