// `flankcam blade --out DIR`: a lofted, tapered, twisted airfoil blade side (not an envelope) and
// suggested initialisation lines for machining it in 1 or more patches.
#include <fmt/format.h>

#include <filesystem>

#include "cli/commands.h"
#include "core/atomic_file.h"
#include "pipeline/output_dir.h"
#include "core/blade.h"
#include "core/number_format.h"

namespace flankcam::cli {

namespace {
struct BladeArgs {
  std::string out;
  BladeOptions blade;
  std::vector<int> patches = {1, 3};
  int lines = 5;
  double offset_mm = 6, overhang_mm = 1;
};

int run_blade(const BladeArgs& args) {
  const Blade b = make_blade(args.blade);
  pipeline::OutputDir out(args.out);
  const BladeOptions& o = args.blade;
  const std::string what = fmt::format(
      "flankcam blade: NACA {:.0f}{:.0f}{:02.0f} suction side, chord {} -> {} mm, span {} mm, twist {} deg, chord {} .. {}",
      100 * o.camber, 10 * o.camber_position, 100 * o.thickness, o.chord_hub, o.chord_tip, o.span, o.twist_deg, o.chord_from,
      o.chord_to);
  write_obj(out.file("blade.obj"), b.mesh, what + ", mm");
  write_file_atomically(out.file("lines.yaml"), [&](std::ostream& s) {
    s << "# " << what << "\n# Initialisation lines (mm), " << args.offset_mm << " mm off the surface, hub end first.\n";
    for (int n : args.patches) {
      s << "patches-" << n << ":\n";
      const auto lines = blade_lines(b, n, args.lines, args.offset_mm, args.overhang_mm);
      for (size_t k = 0; k < lines.size(); ++k) {
        s << "  - # patch " << k + 1 << " of " << n << "\n";
        for (const auto& l : lines[k]) {
          s << "    - [";
          for (size_t i = 0; i < 6; ++i) s << fixed(l[i], 3) << (i < 5 ? ", " : "]\n");
        }
      }
    }
  });
  out.commit();
  fmt::print("{}: {} triangles -> {}/blade.obj, lines -> {}/lines.yaml\n", what, b.mesh.faces.size(), args.out, args.out);
  return 0;
}
}  // namespace

Run add_blade_command(CLI::App& app) {
  auto args = std::make_shared<BladeArgs>();
  CLI::App* cmd = app.add_subcommand("blade", "generate a twisted airfoil blade side (a free-form surface) and init lines");
  cmd->add_option("--out", args->out, "output directory")->required();
  cmd->add_option("--span", args->blade.span, "span, mm")->capture_default_str();
  cmd->add_option("--chord-hub", args->blade.chord_hub, "chord at the hub, mm")->capture_default_str();
  cmd->add_option("--chord-tip", args->blade.chord_tip, "chord at the tip, mm")->capture_default_str();
  cmd->add_option("--twist", args->blade.twist_deg, "twist hub to tip, degrees")->capture_default_str();
  cmd->add_option("--thickness", args->blade.thickness, "NACA thickness, fraction of the chord")->capture_default_str();
  cmd->add_option("--camber", args->blade.camber, "NACA camber, fraction of the chord")->capture_default_str();
  cmd->add_option("--grid-chord", args->blade.grid_chord, "mesh points along the chord")->capture_default_str();
  cmd->add_option("--grid-span", args->blade.grid_span, "mesh points along the span")->capture_default_str();
  cmd->add_option("--patches", args->patches, "patch counts to suggest lines for")->capture_default_str();
  cmd->add_option("--offset", args->offset_mm, "line distance from the surface, mm")->capture_default_str();
  return [args] { return run_blade(*args); };
}

}  // namespace flankcam::cli
