// MuJoCo's contact filter with one more test: a cylinder and a box (or convex mesh) whose
// oriented bounding boxes are apart along one of four axes never reach the narrow phase.
//
// Why: the shaft is a cylinder in a ring of 48 bore boxes. MuJoCo's mid-phase compares bounding
// boxes, and a cylinder's box is square in section, its corners sqrt(2) radii out, so it
// overlaps most of the ring whatever the shaft's pose: 16 bore and 6 counterbore pairs a tick
// went to the general convex collider (~1 us each), where 2 contacts on average came out. A
// separating axis proves that a pair has no contact, so dropping it changes nothing: the
// contacts, and so the simulation, are bit-identical (tests/robot/test_contact_filter.py). The
// four axes are the box's three face normals, where the ring's boxes part from the shaft, and the
// cylinder's axis; along a unit axis u a cylinder of axis a, radius r and half-length h reaches
// h |a.u| + r sqrt(1 - (a.u)^2) from its centre.
//
// MuJoCo calls this (mjcb_contactfilter, one per process) for every candidate pair of geoms not
// listed as an explicit <pair>, in place of its own contype/conaffinity test, which comes first
// here unchanged. It returns 1 to drop the pair. Every other pair of shapes passes as before.
#include <math.h>

#include <mujoco/mujoco.h>

// Pairs farther apart than this along an axis are dropped [m]: a margin for rounding, so that a
// pair the narrow phase would find touching at 0 distance is never dropped.
#define SLACK 1e-9

static double dot3(const double* a, const double* b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The column k of a row-major 3x3 rotation matrix (MuJoCo's xmat): the geom's k-th axis.
static void axis_of(const double* xmat, int k, double* out) {
  out[0] = xmat[k];
  out[1] = xmat[3 + k];
  out[2] = xmat[6 + k];
}

// 1 when the cylinder geom `cyl` and the box or mesh geom `other` (its bounding box in its own
// frame, MuJoCo's geom_aabb) are apart. The cylinder is the discs of radius r centred on its axis,
// c + t a for |t| <= h; the disc at t reaches r sqrt(1 - (a.e)^2) from its centre along a unit e.
// For each of the box's axes e_k, the discs that reach into the box's slab along e_k have t in one
// interval; if the three intervals and [-h, h] have no t in common, no disc, and so no point of
// the cylinder, is inside the box.
static int separated(const mjModel* m, const mjData* d, int cyl, int other) {
  const double r = m->geom_size[3 * cyl], h = m->geom_size[3 * cyl + 1];
  const double* cmat = d->geom_xmat + 9 * cyl;
  const double* omat = d->geom_xmat + 9 * other;
  const double* local = m->geom_aabb + 6 * other;  // centre and half sizes, the geom's frame
  const double margin = m->geom_margin[cyl] + m->geom_margin[other] + m->geom_gap[cyl]
                        + m->geom_gap[other] + SLACK;
  double a[3], e[3], delta[3];
  axis_of(cmat, 2, a);
  for (int i = 0; i < 3; ++i) {
    const double centre = d->geom_xpos[3 * other + i] + omat[3 * i] * local[0]
                          + omat[3 * i + 1] * local[1] + omat[3 * i + 2] * local[2];
    delta[i] = d->geom_xpos[3 * cyl + i] - centre;
  }
  double lo = -h, hi = h;
  for (int k = 0; k < 3; ++k) {
    axis_of(omat, k, e);
    const double along = dot3(a, e), offset = dot3(delta, e);
    const double bound = local[3 + k] + r * sqrt(fmax(0.0, 1.0 - along * along)) + margin;
    if (fabs(along) < 1e-12) {          // the axis parallel to the slab: all discs or none
      if (fabs(offset) > bound) {
        return 1;
      }
      continue;
    }
    double t1 = (-bound - offset) / along, t2 = (bound - offset) / along;
    if (t1 > t2) {
      const double swap = t1;
      t1 = t2;
      t2 = swap;
    }
    lo = fmax(lo, t1);
    hi = fmin(hi, t2);
    if (lo > hi) {
      return 1;
    }
  }
  return 0;
}

static int is_box_like(int type) {
  return type == mjGEOM_BOX || type == mjGEOM_MESH;
}

// mjfConFilt: 1 drops the pair (MuJoCo's bitmask test, then the cylinder's separating axes).
int shaft_contact_filter(const mjModel* m, mjData* d, int g1, int g2) {
  if (!(m->geom_contype[g1] & m->geom_conaffinity[g2])
      && !(m->geom_contype[g2] & m->geom_conaffinity[g1])) {
    return 1;
  }
  const int t1 = m->geom_type[g1], t2 = m->geom_type[g2];
  if (t1 == mjGEOM_CYLINDER && is_box_like(t2)) {
    return separated(m, d, g1, g2);
  }
  if (t2 == mjGEOM_CYLINDER && is_box_like(t1)) {
    return separated(m, d, g2, g1);
  }
  return 0;
}
