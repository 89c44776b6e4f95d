// The wrench the cell's contacts exert on the shaft, summed in compiled code.
//
// Why: the simulation's ground truth (every 10th tick in the robot process's loop, for its topics
// and bags) and the ground-truth wrench estimator (every tick) read it. In Python each contact
// cost ~6 us of array handling around MuJoCo's mj_contactForce, 20-36 us a call in contact; here
// the whole sum takes 1.3 us, its ctypes call included. The arithmetic is the Python version's,
// term by term and in its order; its matrix products were NumPy's, which on this machine's
// OpenBLAS are a chain of fused multiply-adds, written out here (the file is compiled with no
// other fusing): the numbers are the Python version's to the bit on 23,864 recorded contact
// states, and the same on any machine, where NumPy's depended on its BLAS kernel
// (tests/robot/test_mujoco_world.py).
#include <math.h>

#include <mujoco/mujoco.h>

// frame^T v for a 3x3 row-major frame (a contact's: its rows the normal and the two tangents),
// as OpenBLAS's matrix-vector kernel sums it: one fused multiply-add per column.
static void frame_transposed_times(const mjtNum* frame, const mjtNum* v, mjtNum* out) {
  for (int j = 0; j < 3; ++j) {
    out[j] = fma(frame[6 + j], v[2], fma(frame[3 + j], v[1], frame[j] * v[0]));
  }
}

// The contacts of `geom` in d->contact (those of the last collision), their forces as the
// solver left them: out[0..2] the force and out[3..5] the torque about the origin of `body`, both
// in that body's frame (d->xpos, d->xmat: the caller brings its kinematics up to date). A contact
// acts on its second geom along its normal; on the first with the opposite sign.
void shaft_contact_wrench(const mjModel* m, const mjData* d, int geom, int body, mjtNum* out) {
  const mjtNum* origin = d->xpos + 3 * body;
  const mjtNum* rotation = d->xmat + 9 * body;
  mjtNum force[3] = {0.0, 0.0, 0.0}, torque[3] = {0.0, 0.0, 0.0};
  for (int i = 0; i < d->ncon; ++i) {
    const mjContact* contact = d->contact + i;
    if (contact->geom[0] != geom && contact->geom[1] != geom) {
      continue;
    }
    const mjtNum sign = contact->geom[0] == geom ? -1.0 : 1.0;
    mjtNum f6[6], f[3], t[3], arm[3];
    mj_contactForce(m, d, i, f6);
    frame_transposed_times(contact->frame, f6, f);
    frame_transposed_times(contact->frame, f6 + 3, t);
    for (int k = 0; k < 3; ++k) {
      f[k] = sign * f[k];
      arm[k] = contact->pos[k] - origin[k];
    }
    const mjtNum cross[3] = {arm[1] * f[2] - arm[2] * f[1], arm[2] * f[0] - arm[0] * f[2],
                             arm[0] * f[1] - arm[1] * f[0]};
    for (int k = 0; k < 3; ++k) {
      force[k] += f[k];
      torque[k] += cross[k] + sign * t[k];
    }
  }
  frame_transposed_times(rotation, force, out);
  frame_transposed_times(rotation, torque, out + 3);
}
