// STEP and IGES models through Open CASCADE: the faces a user picks (numbered from 1 in the order of
// TopExp_Explorer over faces, the order DRAW's `explode` uses), sewn where they share edges,
// tessellated by BRepMesh at a chordal deviation tied to the job, oriented by the B-rep, in mm.
// OCCT stays behind this header.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace flankcam {

struct CadOptions {
  std::vector<int> faces;               // 1-based face numbers; empty: every face
  double chordal_deflection_mm = 0.01;  // BRepMesh linear deflection (surface to triangle), mm
  double angular_deflection_rad = 0.1;  // BRepMesh angular deflection between neighbouring triangles
  double sewing_tolerance_mm = 0.01;    // faces whose edges lie this close are sewn (joined)
  std::vector<int> fine_faces;          // of `faces`, these at fine_deflection_mm (the flank inside the part)
  double fine_deflection_mm = 0;
  std::string validate() const;         // empty when valid
};

// A tessellated selection of faces: one welded, consistently oriented mesh in mm.
struct CadMesh {
  LoadedMesh loaded;                  // mm; normals point out of the material (the B-rep's orientation)
  std::vector<int> triangle_face;     // per triangle: its face number (1-based)
  int faces_in_file = 0;
  std::string units;                  // the file's length unit as written ("MILLIMETRE", "INCH", "IN", ...)
  std::string note;                   // e.g. "lengths in INCH, converted to mm"; empty for mm files
};

// Reads .step/.stp/.iges/.igs. Throws InputError "FILE: ..." (one line) for a missing or unreadable
// file, no faces, a face number out of range or listed twice, a face that does not tessellate.
[[nodiscard]] CadMesh load_cad(const std::string& path, const CadOptions& options);

struct FaceInfo {
  int number = 0;                 // 1-based
  std::string surface;            // "plane", "cylinder", "bspline", ...
  double area_mm2 = 0;
  BoundingBox box;                // mm
  Eigen::Vector3d centroid_mm = Eigen::Vector3d::Zero();
  std::vector<int> neighbours;    // faces sharing an edge with this one (after sewing), ascending
};

struct CadFaces {
  std::vector<FaceInfo> faces;
  std::string units, note;        // as in CadMesh
};

// Every face of the model, with its neighbours after sewing at `sewing_tolerance_mm`.
[[nodiscard]] CadFaces list_faces(const std::string& path, double sewing_tolerance_mm = 0.01);

// The job's default chordal deflections: a twentieth of the fit tolerance for the design surface, a
// tenth of the clearance for the part (its tessellation error shifts the collision verdicts).
[[nodiscard]] inline double surface_deflection_mm(double tolerance_mm) { return tolerance_mm / 20; }
[[nodiscard]] inline double part_deflection_mm(double clearance_mm) { return clearance_mm / 10; }

// The job's `part:`: every face at `part_deflection_mm`; when it is the surface's own model, the
// surface's faces (all when `surface_faces` is empty) at `surface_deflection_mm`, so that the flank's
// coarse part tessellation does not show up as a gouge of the fitted tool. Mesh files: load_mesh.
[[nodiscard]] CadMesh load_part_file(const std::string& part, const std::string& surface,
                                     const std::vector<int>& surface_faces, double part_deflection_mm,
                                     double surface_deflection_mm);

// True for the extensions load_cad reads (case-insensitive).
[[nodiscard]] bool is_cad_file(const std::string& path);

// The job's `surface:` / `part:`: STEP/IGES through load_cad (faces empty: every face), anything else
// through load_mesh (then `faces` must be empty). The note says what was converted.
[[nodiscard]] CadMesh load_surface_file(const std::string& path, const std::vector<int>& faces,
                                        double chordal_deflection_mm);

}  // namespace flankcam
