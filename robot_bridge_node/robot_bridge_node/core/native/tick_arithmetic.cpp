// The 1 kHz tick's elementwise arithmetic in compiled code, each part one call from Python:
// the safety filter's joint-torque limits, and the simulated arm's friction and sensor readings.
//
// Why: on Python floats the torque limits cost ~5 us a tick (in NumPy ~15 us), and the simulated
// arm's friction and readings took ~10 NumPy calls a step, each ~0.5 us in the tick (its caches
// cold after the physics step); here each is one call of well under a microsecond. The formulas
// and their documentation stay in ``safety.py`` (``SafetyFilter.limit_torques``) and
// ``sim_robot_node/core/arm_imperfections.py`` (``ImperfectArm``), which own the parameters and
// the errors' wording. Only exactly rounded operations run here (+, -, *, comparisons), each in
// the order NumPy did them; a bound is NumPy's ``maximum`` / ``minimum`` written out (``a`` if
// ``a >= b`` or ``a`` is NaN, else ``b``: a NaN wins). So every result is NumPy's to the bit,
// NaN and -0.0 included. Built with -ffp-contract=off and without -ffast-math or -march: no
// operation is fused or reordered. (A transcendental such as ``tanh`` stays NumPy's: its SIMD
// loops round differently from libm's.)
#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
// An array NumPy writes into and compiled code reads: float64 and C-contiguous as given, never a
// converted copy (its arguments are ``noconvert``).
using Buffer = py::array_t<double, py::array::c_style>;

namespace {

// NumPy's maximum(a, b) / minimum(a, b) for one pair: a NaN in ``a`` wins (``b`` is never NaN
// where these are used with a limit; where it is, NumPy's result is ``b``, as here).
inline double at_least(double a, double b) { return (a >= b || a != a) ? a : b; }
inline double at_most(double a, double b) { return (a <= b || a != a) ? a : b; }

std::string shape_of(const py::array& a) {
  std::ostringstream text;
  text << "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) text << (i ? ", " : "") << a.shape(i);
  text << (a.ndim() == 1 ? ",)" : ")");
  return text.str();
}

}  // namespace

// The joint-torque limits of an arm, and the last command they let through (the rate limit's
// reference). ``limit`` is ``SafetyFilter.limit_torques``'s arithmetic.
class TorqueLimiter {
 public:
  TorqueLimiter(std::vector<double> torque, std::vector<double> rate,
                std::vector<double> velocity, double brake_damping)
      : torque_(std::move(torque)), rate_(std::move(rate)), velocity_(std::move(velocity)),
        brake_damping_(brake_damping), last_(torque_.size(), 0.0) {
    if (rate_.size() != torque_.size() || velocity_.size() != torque_.size())
      throw std::invalid_argument("torque, rate and velocity limits need one entry per joint");
    for (double t : torque_) floor_.push_back(-t);
  }

  // Forget the last command (no rate limit on the next), or start from ``tau``.
  void reset(py::object tau) {
    if (tau.is_none()) {
      has_last_ = false;
      return;
    }
    Array values = joint_values("tau", tau);
    const double* v = values.data();
    for (std::size_t i = 0; i < last_.size(); ++i) last_[i] = v[i];
    has_last_ = true;
  }

  // ``tau`` braked where ``dq`` (optional) is past the velocity limits, clipped to the torque
  // limits, then to the rate limit around the last command over ``dt``; that is the new last.
  Array limit(py::object tau, double dt, py::object dq) {
    Array torques = joint_values("tau", tau);
    const std::size_t n = torque_.size();
    Array out(static_cast<py::ssize_t>(n));
    double* t = out.mutable_data();
    const double* in = torques.data();
    for (std::size_t i = 0; i < n; ++i) t[i] = in[i];
    if (!dq.is_none()) {
      Array speeds_array = joint_values("dq", dq);
      const double* s = speeds_array.data();
      bool within_all = true;
      for (std::size_t i = 0; i < n; ++i)
        if (!(-velocity_[i] <= s[i] && s[i] <= velocity_[i])) within_all = false;
      if (!within_all) {
        for (std::size_t i = 0; i < n; ++i) {
          const double v = velocity_[i];
          const double within = at_most(at_least(s[i], -v), v);
          t[i] = t[i] - brake_damping_ * (s[i] - within);
        }
      }
    }
    for (std::size_t i = 0; i < n; ++i) t[i] = at_most(at_least(t[i], floor_[i]), torque_[i]);
    if (has_last_) {
      for (std::size_t i = 0; i < n; ++i) {
        const double step = rate_[i] * dt;
        t[i] = at_most(at_least(t[i], last_[i] - step), last_[i] + step);
      }
    }
    for (std::size_t i = 0; i < n; ++i) last_[i] = t[i];
    has_last_ = true;
    return out;
  }

  std::size_t joints() const { return torque_.size(); }

 private:
  // ``value`` as a C-contiguous float64 array of one entry per joint, or ValueError naming it.
  Array joint_values(const char* name, const py::object& value) const {
    Array array = Array::ensure(value);
    if (!array) {
      PyErr_Clear();
      throw py::value_error(std::string(name) + " must be an array of numbers");
    }
    if (array.ndim() != 1 || static_cast<std::size_t>(array.shape(0)) != torque_.size()) {
      std::ostringstream msg;
      msg << name << " must have one entry per joint (" << torque_.size() << "), got shape "
          << shape_of(array);
      throw py::value_error(msg.str());
    }
    return array;
  }

  std::vector<double> torque_, rate_, velocity_, floor_;
  double brake_damping_;
  std::vector<double> last_;
  bool has_last_ = false;
};

// A simulated arm's friction and sensor readings (ImperfectArm), with its constants and the
// buffers NumPy writes into (``tanh(dq / velocity)`` before each ``friction_applied``, the noise
// stream's normals whenever they run out) held from the start: each call converts only the
// state it is given (~0.1 us an array).
class ArmErrors {
 public:
  ArmErrors(Array coulomb, Array viscous, Buffer tanh_scaled, Array scale, Array bias,
            Buffer normals)
      : n_(coulomb.size()), coulomb_(std::move(coulomb)), viscous_(std::move(viscous)),
        tanh_scaled_(std::move(tanh_scaled)), scale_(std::move(scale)), bias_(std::move(bias)),
        normals_(std::move(normals)) {
    if (viscous_.size() != n_ || tanh_scaled_.size() != n_ || scale_.size() != 3 * n_ ||
        bias_.size() != 3 * n_ || normals_.size() < 4 * n_)
      throw py::value_error("ArmErrors: coulomb, viscous and tanh_scaled need n entries, scale "
                            "and bias 3n, normals at least 4n");
  }

  // ``tau - (coulomb * tanh_scaled + viscous * dq)``, entry by entry in NumPy's order: the
  // torque reaching the links of a command ``tau`` (``tanh_scaled``: NumPy's tanh(dq / v)).
  Array friction_applied(const Array& tau, const Array& dq) const {
    check_joints("tau", tau);
    check_joints("dq", dq);
    Array out(n_);
    double* o = out.mutable_data();
    const double *t = tau.data(), *v = dq.data(), *h = tanh_scaled_.data(),
                 *c = coulomb_.data(), *d = viscous_.data();
    for (py::ssize_t i = 0; i < n_; ++i) {
      const double coulomb_part = c[i] * h[i];
      const double viscous_part = d[i] * v[i];
      const double friction = coulomb_part + viscous_part;
      o[i] = t[i] - friction;
    }
    return out;
  }

  // ``[q, dq, tau] + bias + normals[first:first + 3n] * scale`` (3n,), entry by entry in
  // NumPy's order (the sum first, then the noise): a driver's reading of the true state.
  Array reading(const Array& q, const Array& dq, const Array& tau, py::ssize_t first) const {
    check_joints("q", q);
    check_joints("dq", dq);
    check_joints("tau", tau);
    if (first < 0 || first + 3 * n_ > normals_.size())
      throw py::value_error("reading: the normals from " + std::to_string(first) +
                            " run past the buffer's end");
    Array out(3 * n_);
    double* o = out.mutable_data();
    const double* parts[3] = {q.data(), dq.data(), tau.data()};
    const double *z = normals_.data() + first, *s = scale_.data(), *b = bias_.data();
    for (py::ssize_t k = 0; k < 3; ++k)
      for (py::ssize_t i = 0; i < n_; ++i) {
        const py::ssize_t j = k * n_ + i;
        const double noise = z[j] * s[j];
        const double biased = parts[k][i] + b[j];
        o[j] = biased + noise;
      }
    return out;
  }

 private:
  void check_joints(const char* name, const Array& value) const {
    if (value.ndim() != 1 || value.size() != n_)
      throw py::value_error(std::string(name) + " must have one entry per joint (" +
                            std::to_string(n_) + ")");
  }

  py::ssize_t n_;
  Array coulomb_, viscous_;
  Buffer tanh_scaled_;
  Array scale_, bias_;
  Buffer normals_;
};

PYBIND11_MODULE(_tick_arithmetic, m) {
  m.doc() = "The 1 kHz tick's elementwise arithmetic: torque limits, a simulated arm's errors.";
  py::class_<ArmErrors>(m, "ArmErrors")
      .def(py::init<Array, Array, Buffer, Array, Array, Buffer>(), py::arg("coulomb"),
           py::arg("viscous"), py::arg("tanh_scaled").noconvert(), py::arg("scale"),
           py::arg("bias"), py::arg("normals").noconvert())
      .def("friction_applied", &ArmErrors::friction_applied, py::arg("tau"), py::arg("dq"))
      .def("reading", &ArmErrors::reading, py::arg("q"), py::arg("dq"), py::arg("tau"),
           py::arg("first"));
  py::class_<TorqueLimiter>(m, "TorqueLimiter")
      .def(py::init<std::vector<double>, std::vector<double>, std::vector<double>, double>(),
           py::arg("torque"), py::arg("rate"), py::arg("velocity"), py::arg("brake_damping"))
      .def("reset", &TorqueLimiter::reset, py::arg("tau"))
      .def("limit", &TorqueLimiter::limit, py::arg("tau"), py::arg("dt"),
           py::arg("dq") = py::none())
      .def_property_readonly("joints", &TorqueLimiter::joints);
}
