// The safety filter's joint-torque limits in compiled code: one call from Python per 1 kHz tick.
//
// Why: on Python floats the limits cost ~5 us a tick (a NumPy version ~15 us), one of the
// largest parts of the tick outside the physics; here ~0.5 us. The formulas and their
// documentation stay in ``safety.py`` (``SafetyFilter.limit_torques``), which owns the limits and
// the errors' wording. Every bound is NumPy's ``maximum`` / ``minimum`` written out (``a`` if
// ``a >= b`` or ``a`` is NaN, else ``b``: a NaN wins), and each sum and product is the one
// ``safety.py`` wrote, in its order, so the result is NumPy's to the bit, NaN and -0.0 included.
// Built without -ffast-math and without FMA (no -march), so no operation is fused or reordered.
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

PYBIND11_MODULE(_torque_limits, m) {
  m.doc() = "Compiled joint-torque limits of the safety filter (safety.SafetyFilter).";
  py::class_<TorqueLimiter>(m, "TorqueLimiter")
      .def(py::init<std::vector<double>, std::vector<double>, std::vector<double>, double>(),
           py::arg("torque"), py::arg("rate"), py::arg("velocity"), py::arg("brake_damping"))
      .def("reset", &TorqueLimiter::reset, py::arg("tau"))
      .def("limit", &TorqueLimiter::limit, py::arg("tau"), py::arg("dt"),
           py::arg("dq") = py::none())
      .def_property_readonly("joints", &TorqueLimiter::joints);
}
