// `flankcam faces MODEL [--out DIR]`: the faces of a STEP/IGES model (number, surface type, area,
// bounding box, neighbours) and, with --out, faces.svg / faces.html drawing them numbered at their
// centroids, so a user can pick the flank for a job's `surface: {file: ..., faces: [...]}`.
#include <fmt/format.h>

#include <optional>

#include "cli/commands.h"
#include "pipeline/faces.h"

namespace flankcam::cli {

namespace {
struct FacesArgs {
  std::string model, out;
  double sewing_mm = 0.01;
};

int run_faces(const FacesArgs& args) {
  std::optional<pipeline::OutputDir> out;  // checked before the model is read
  if (!args.out.empty()) out.emplace(args.out);
  const pipeline::FacesOverview o = pipeline::faces_overview(args.model, args.sewing_mm, out.has_value());
  fmt::print("{}\n", o.head);
  for (const auto& l : o.table) fmt::print("{}\n", l);
  if (!out) return 0;
  pipeline::write_faces(o, *out);
  fmt::print("overview -> {}/faces.svg, {}/faces.html\n", args.out, args.out);
  return 0;
}
}  // namespace

Run add_faces_command(CLI::App& app) {
  auto args = std::make_shared<FacesArgs>();
  CLI::App* cmd = app.add_subcommand("faces", "list the faces of a STEP/IGES model and draw them numbered");
  cmd->add_option("model", args->model, "STEP (.step, .stp) or IGES (.iges, .igs) model")->required();
  cmd->add_option("--out", args->out, "write faces.svg and faces.html into this directory (written completely or not at all)");
  cmd->add_option("--sewing", args->sewing_mm, "faces whose edges lie this close are neighbours, mm")->capture_default_str();
  return [args] { return run_faces(*args); };
}

}  // namespace flankcam::cli
