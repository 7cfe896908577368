// `flankcam faces`: the faces of a STEP/IGES model as a table (number, surface type, area, bounding
// box, neighbours) and a picture that draws them numbered at their centroids, so a user can pick the
// flank for a job's `surface: {file: ..., faces: [...]}`.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "cad/cad_reader.h"
#include "pipeline/output_dir.h"

namespace flankcam::pipeline {

struct FacesOverview {
  std::string model;
  CadFaces faces;
  std::string head;                // "MODEL: N faces, mm"
  std::vector<std::string> table;  // header row, then one row per face
  std::optional<CadMesh> mesh;     // a coarse tessellation for the picture (with_picture)
};

// Reads the model's faces (`sewing_mm`: edges this close make faces neighbours) and, with
// `with_picture`, tessellates it at 1/300 of its size for the overview.
[[nodiscard]] FacesOverview faces_overview(const std::string& model, double sewing_mm, bool with_picture);

// faces.svg (two opposite views, faces numbered) and faces.html (the picture and the table).
void write_faces(const FacesOverview& overview, OutputDir& out);

}  // namespace flankcam::pipeline
