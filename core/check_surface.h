// The part as a check surface (issue 15): what the fit keeps the tool out of, and what the
// collision check judges besides the design surface. A part mesh usually contains a coarser twin of
// the design surface Φ (the blade flank being cut); the cutter touches Φ by construction, so that
// twin is left out and Φ itself is judged with the fitted tolerance instead.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "core/closest_point.h"
#include "core/mesh.h"

namespace flankcam {

struct CheckPart {
  TriMesh mesh;            // the part without Φ's twin, faces out of the material
  int twin_faces = 0;      // faces left out: on Φ (all three corners within `within`, normal along Φ's)
  bool turned_outward = false;  // a closed part whose faces pointed inwards was turned
  std::vector<char> twin;       // per face of the part given: 1 for a face of Φ's twin
  // The farthest a twin face stands off Φ (its centroid and edge midpoints): a coarse twin's
  // chords sag off the fine design surface (0.05 mm on the HECC impeller's blade).
  double twin_sag = 0;
};

// The part's faces whose three corners lie within `within` of Φ (its boundary included) and whose
// normal is within 60 degrees of Φ's are Φ's twin and left out (Φ's orientation relative to the part
// is that of the most of those faces, so the other side of a blade thinner than `within` stays). A closed part
// (no boundary edge) is oriented outward by its signed volume; an open one must already have its
// faces pointing out of the material (the convention of the part files flankcam reads).
[[nodiscard]] CheckPart check_part(const TriMesh& part, const SurfaceIndex& design, double within);

// Signed volume of a mesh (positive for a closed, outward oriented one).
[[nodiscard]] double signed_volume(const TriMesh& mesh);

// The two meshes as one (b's vertices appended, its faces re-indexed).
[[nodiscard]] TriMesh merged(const TriMesh& a, const TriMesh& b);

}  // namespace flankcam
