// Built-in triangle meshes for synthetic scenes. Each is closed, outward-facing (counter-clockwise
// seen from outside), centred at the origin and fits inside the unit sphere.
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

TriangleMesh MakeIcoSphere(double radius, int subdivisions);
TriangleMesh MakeTorus(double major_radius, double minor_radius, int major_segments,
                       int minor_segments);
// A box with rounded edges and corners: half-size `half_extent`, rounding radius `rounding`.
TriangleMesh MakeRoundedBox(double half_extent, double rounding, int segments_per_face);
// A sphere with three smooth dents (concavities) and a thin rod (thin structure) sticking out.
TriangleMesh MakeDentedSphereWithRod(int subdivisions);

// Detailed shapes (detailed_shapes.cc). Sharp-edged ones have no vertex normals (face normals
// are exact).
// A gear: deep trapezoidal teeth around a hole through its middle, tilted.
TriangleMesh MakeGear(int teeth, int samples_per_tooth);
// A U-shaped block with a narrow, deep slot (0.1 wide, 0.9 deep), tilted.
TriangleMesh MakeSlottedBlock(int segments);
// A trefoil knot as a thin tube (radius 0.12) whose strands pass close to each other.
TriangleMesh MakeTrefoilKnot(int segments, int sides);
// A flat slab 1.4 x 1.4 x 0.06 standing upright: with the "print" texture, a printed wall whose
// true normals are constant over each face.
TriangleMesh MakePrintedWall();

// Names accepted by MakeShape: sphere, torus, rounded_box, dented, gear, slot, knot, wall (all
// listed by ShapeNames()).
std::vector<std::string> ShapeNames();
// Shapes with sharp edges (gear, slot, wall): built without vertex normals, so they shade and
// report their face normals exactly; fusion at a voxel's size rounds their edges.
bool ShapeHasSharpEdges(const std::string& name);
// Builds a shape by name at a detail level (0 = coarse .. 2 = fine); false if the name is unknown.
bool MakeShape(const std::string& name, int detail, TriangleMesh* mesh);

}  // namespace mgsr
