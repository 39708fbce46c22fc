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

// Names accepted by MakeShape: sphere, torus, rounded_box, dented (all listed by ShapeNames()).
std::vector<std::string> ShapeNames();
// Builds a shape by name at a detail level (0 = coarse .. 2 = fine); false if the name is unknown.
bool MakeShape(const std::string& name, int detail, TriangleMesh* mesh);

}  // namespace mgsr
