// The per-tick arithmetic of the torque loop in compiled code: the wrench EKF's predict/correct
// and the hybrid force/impedance law, each one call from Python per 1 kHz tick.
//
// Why: in NumPy each tick made ~10 Pinocchio calls and ~60 small-array operations, every one
// paying Python's call overhead on 7x7 to 20x20 matrices (70-90 us a tick in the loop, more than
// the physics step of the learner's episodes). Here the same Pinocchio algorithms (their C++
// templates, the library the Python bindings wrap) and the same formulas take ~10 us. The
// formulas and their documentation stay in ``wrench_ekf.py`` and ``impedance.py``, whose classes
// own the configuration, validation and state that Python reads; these kernels only compute.
//
// The robot model arrives as Pinocchio's own serialisation of the Python-side model (with the
// tool frame and payload already added), so Python and C++ can never disagree about the robot.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/serialization.hpp>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

namespace py = pybind11;
namespace pin = pinocchio;

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat3 = Eigen::Matrix3d;
using Jac = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using RowMat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
using VecIn = Eigen::Ref<const Vec>;

namespace {

pin::Model model_from_string(const std::string& serialised) {
  pin::Model model;
  model.loadFromString(serialised);
  return model;
}

// Raises ValueError (pybind11 maps std::invalid_argument) naming the bad input.
void check_input(const char* name, const VecIn& value, Eigen::Index n) {
  if (value.size() != n) {
    std::ostringstream msg;
    msg << name << " must have shape (" << n << ",), got (" << value.size() << ",)";
    throw std::invalid_argument(msg.str());
  }
  if (!value.allFinite()) {
    std::ostringstream msg;
    msg << name << " contains NaN or inf: [" << value.transpose() << "]";
    throw std::invalid_argument(msg.str());
  }
}

// Copies the upper triangle of a symmetric matrix into the lower one: computeMinverse fills only
// the upper triangle.
void symmetrise_from_upper(Mat& m) {
  m.triangularView<Eigen::StrictlyLower>() = m.transpose().triangularView<Eigen::StrictlyLower>();
}

}  // namespace

// Extended Kalman filter over x = [q, dq, F] (see wrench_ekf.py for the model and its reasons).
// The state and covariance live here; Python reads copies. Every buffer is allocated once; the
// covariance steps use the structure of F (identity plus three blocks) and the Cholesky factor
// of the innovation covariance instead of dense products.
class WrenchEkfKernel {
 public:
  WrenchEkfKernel(const std::string& model, int tool_frame, const VecIn& measurement_var,
                  const VecIn& process_rate, const VecIn& initial_var)
      : model_(model_from_string(model)), data_(model_), tool_(tool_frame),
        n_(model_.nv), nz_(2 * model_.nv), nx_(2 * model_.nv + 6),
        r_(measurement_var), q_rate_(process_rate), p0_(initial_var.asDiagonal()),
        llt_(2 * model_.nv) {
    if (model_.nq != model_.nv)
      throw std::invalid_argument("the EKF needs nq == nv (revolute or prismatic joints)");
    if (measurement_var.size() != nz_ || process_rate.size() != nx_ || initial_var.size() != nx_)
      throw std::invalid_argument("noise vectors must have 2n, 2n + 6 and 2n + 6 entries");
    x_ = Vec::Zero(nx_);
    p_ = p0_;
    fp_ = Mat::Zero(nx_, nx_);
    s_ = Mat::Zero(nz_, nz_);
    w_ = Mat::Zero(nz_, nx_);
    m_inv_ = Mat::Zero(n_, n_);
    a_w_ = Mat::Zero(n_, 6);
    aw_p_ = Mat::Zero(n_, nx_);
    p_aw_ = Mat::Zero(nx_, n_);
    a_ = Vec::Zero(n_);
    innovation_ = Vec::Zero(nz_);
    jac_.setZero(6, n_);
    wrench_tool_.setZero();
  }

  void reset(const VecIn& q) {
    check_input("q", q, n_);
    x_.setZero();
    x_.head(n_) = q;
    p_ = p0_;
    wrench_tool_.setZero();
  }

  // One predict/correct step; returns the tool-frame wrench (Fx, Fy, Fz, Tx, Ty, Tz).
  Vec6 update(const VecIn& q, const VecIn& dq, const VecIn& tau_cmd, double dt) {
    check_input("q", q, n_);
    check_input("dq", dq, n_);
    check_input("tau_cmd", tau_cmd, n_);
    if (!(dt > 0.0 && std::isfinite(dt))) {
      std::ostringstream msg;
      msg << "dt must be a finite positive time step [s], got " << dt;
      throw std::invalid_argument(msg.str());
    }
    predict(tau_cmd, dt);
    correct(q, dq);
    read_out();
    return wrench_tool_;
  }

  Vec wrench_base() const { return x_.tail(6); }
  Mat covariance() const { return p_; }

 private:
  void predict(const VecIn& tau_cmd, double dt) {
    const auto q = x_.head(n_);
    const auto dq = x_.segment(n_, n_);
    m_inv_ = pin::computeMinverse(model_, data_, q);
    symmetrise_from_upper(m_inv_);
    pin::nonLinearEffects(model_, data_, q, dq);
    pin::computeFrameJacobian(model_, data_, q, tool_, pin::LOCAL_WORLD_ALIGNED, jac_);
    // Semi-implicit Euler: dq+ = dq + dt (a + A w), q+ = q + dt dq+, w+ = w, with
    // a = M^-1 (tau - nle) and A = M^-1 J^T. F = I + E, E's blocks: dt I (q rows, dq columns),
    // dt^2 A (q rows, w columns), dt A (dq rows, w columns).
    a_w_.noalias() = m_inv_ * jac_.transpose();
    a_.noalias() = m_inv_ * (tau_cmd - data_.nle);
    a_.noalias() += a_w_ * x_.tail(6);
    x_.segment(n_, n_) += dt * a_;
    x_.head(n_) += dt * x_.segment(n_, n_);
    // P+ = F P F^T + Q dt, as (F P) F^T with F P = P + E P and (F P) F^T = F P + (F P) E^T.
    aw_p_.noalias() = a_w_ * p_.bottomRows(6);
    fp_ = p_;
    fp_.topRows(n_) += dt * p_.middleRows(n_, n_) + (dt * dt) * aw_p_;
    fp_.middleRows(n_, n_) += dt * aw_p_;
    p_aw_.noalias() = fp_.rightCols(6) * a_w_.transpose();
    p_ = fp_;
    p_.leftCols(n_) += dt * fp_.middleCols(n_, n_) + (dt * dt) * p_aw_;
    p_.middleCols(n_, n_) += dt * p_aw_;
    p_.diagonal() += dt * q_rate_;
  }

  void correct(const VecIn& q, const VecIn& dq) {
    // With S = H P H^T + R = L L^T and W = L^-1 H P: K (z - H x) = W^T L^-1 (z - H x) and
    // K H P = W^T W (H = [I 0]).
    s_ = p_.topLeftCorner(nz_, nz_);
    s_.diagonal() += r_;
    llt_.compute(s_);
    if (llt_.info() != Eigen::Success)
      throw std::runtime_error("innovation covariance not positive definite");
    w_ = p_.topRows(nz_);
    llt_.matrixL().solveInPlace(w_);
    innovation_.head(n_) = q - x_.head(n_);
    innovation_.tail(n_) = dq - x_.segment(n_, n_);
    llt_.matrixL().solveInPlace(innovation_);
    x_.noalias() += w_.transpose() * innovation_;
    p_.noalias() -= w_.transpose() * w_;
    fp_ = p_.transpose();                       // symmetrise: (P + P^T) / 2
    p_ += fp_;
    p_ *= 0.5;
  }

  void read_out() {
    pin::forwardKinematics(model_, data_, x_.head(n_));
    const Mat3& rot = pin::updateFramePlacement(model_, data_, tool_).rotation();
    wrench_tool_.head(3).noalias() = rot.transpose() * x_.segment(nz_, 3);
    wrench_tool_.tail(3).noalias() = rot.transpose() * x_.tail(3);
  }

  pin::Model model_;
  pin::Data data_;
  pin::FrameIndex tool_;
  Eigen::Index n_, nz_, nx_;
  Vec r_, q_rate_;
  Mat p0_, p_, fp_, s_, w_, m_inv_, a_w_, aw_p_, p_aw_;
  Vec x_, a_, innovation_;
  Eigen::LLT<Mat> llt_;
  Jac jac_;
  Vec6 wrench_tool_;
};

// Hybrid task-space force/impedance law (see impedance.py for the law and its gains).
class ImpedanceKernel {
 public:
  ImpedanceKernel(const std::string& model, int tool_frame, const VecIn& stiffness,
                  const VecIn& damping, double k_null, double d_null, double d_joint)
      : model_(model_from_string(model)), data_(model_), tool_(tool_frame), n_(model_.nv),
        stiffness_(stiffness), damping_(damping), k_null_(k_null), d_null_(d_null),
        d_joint_(d_joint) {
    if (stiffness.size() != 6 || damping.size() != 6)
      throw std::invalid_argument("stiffness and damping need 6 entries (EEF x, y, z, rx, ry, rz)");
    reference_position_.setZero();
    reference_rotation_.setIdentity();
    q_null_ = Vec::Zero(n_);
    jac_.setZero(6, n_);
  }

  // Tool position, rotation and Jacobian (LOCAL_WORLD_ALIGNED) at q.
  py::tuple kinematics(const VecIn& q) {
    update_kinematics(q);
    return py::make_tuple(position_, rotation_, jac_);
  }

  void set_reference(const VecIn& position, const Eigen::Ref<const RowMat3>& rotation) {
    reference_position_ = position;
    reference_rotation_ = rotation;
  }

  void set_posture(const VecIn& q_null) { q_null_ = q_null; }

  // The EEF-frame stiffness and damping (x, y, z, rx, ry, rz): the task's, or the hold's.
  void set_gains(const VecIn& stiffness, const VecIn& damping) {
    check_input("stiffness", stiffness, 6);
    check_input("damping", damping, 6);
    if ((stiffness.array() < 0.0).any() || (damping.array() < 0.0).any())
      throw std::invalid_argument("stiffness and damping entries must be >= 0");
    stiffness_ = stiffness;
    damping_ = damping;
  }

  // Joint torques for this tick, and the tool's position, rotation and twist it was computed at.
  py::tuple step(const VecIn& q, const VecIn& dq, const Eigen::Ref<const Vec6>& wrench_ff) {
    update_kinematics(q);
    const Vec6 twist = jac_ * dq;
    Eigen::Matrix<double, 6, 6> rot6 = Eigen::Matrix<double, 6, 6>::Zero();
    rot6.topLeftCorner<3, 3>() = rotation_;
    rot6.bottomRightCorner<3, 3>() = rotation_;
    const Mat jac_eef_t = jac_.transpose() * rot6;      // EEF-frame wrench -> joint torques
    Vec6 error;
    error.head<3>() = reference_position_ - position_;
    error.tail<3>() = pin::log3(Mat3(reference_rotation_ * rotation_.transpose()));
    const Vec6 wrench = stiffness_.cwiseProduct(rot6.transpose() * error)
        - damping_.cwiseProduct(jac_eef_t.transpose() * dq) - wrench_ff;
    const Vec tau_task = jac_eef_t * wrench;
    const Vec posture = k_null_ * (q_null_ - q) - d_null_ * dq;
    // Projector I - J^T (J J^T)^-1 J, regularised near singularities.
    Eigen::Matrix<double, 6, 6> jjt = jac_ * jac_.transpose();
    jjt.diagonal().array() += 1e-6;
    Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(jjt);
    if (llt.info() != Eigen::Success)
      throw std::runtime_error("null-space projection failed (J J^T not positive definite)");
    const Vec6 projected = llt.solve(jac_ * posture);
    const Vec null = posture - jac_.transpose() * projected;
    const Vec nle = pin::nonLinearEffects(model_, data_, q, dq);
    const Vec tau = tau_task + null - d_joint_ * dq + nle;
    return py::make_tuple(tau, position_, rotation_, twist);
  }

 private:
  void update_kinematics(const VecIn& q) {
    if (q.size() != n_) throw std::invalid_argument("q has the wrong number of joints");
    pin::computeJointJacobians(model_, data_, q);
    pin::updateFramePlacements(model_, data_);
    const pin::SE3& placement = data_.oMf[tool_];
    position_ = placement.translation();
    rotation_ = placement.rotation();
    jac_.setZero();
    pin::getFrameJacobian(model_, data_, tool_, pin::LOCAL_WORLD_ALIGNED, jac_);
  }

  pin::Model model_;
  pin::Data data_;
  pin::FrameIndex tool_;
  Eigen::Index n_;
  Vec6 stiffness_, damping_;
  double k_null_, d_null_, d_joint_;
  Eigen::Vector3d reference_position_, position_;
  Mat3 reference_rotation_, rotation_;
  Vec q_null_;
  Jac jac_;
};

PYBIND11_MODULE(_torque_kernels, m) {
  m.doc() = "Compiled per-tick arithmetic of the torque loop (wrench EKF, impedance law).";
  py::class_<WrenchEkfKernel>(m, "WrenchEkfKernel")
      .def(py::init<const std::string&, int, const VecIn&, const VecIn&, const VecIn&>(),
           py::arg("model"), py::arg("tool_frame"), py::arg("measurement_var"),
           py::arg("process_rate"), py::arg("initial_var"))
      .def("reset", &WrenchEkfKernel::reset)
      .def("update", &WrenchEkfKernel::update)
      .def_property_readonly("wrench_base", &WrenchEkfKernel::wrench_base)
      .def_property_readonly("covariance", &WrenchEkfKernel::covariance);
  py::class_<ImpedanceKernel>(m, "ImpedanceKernel")
      .def(py::init<const std::string&, int, const VecIn&, const VecIn&, double, double,
                    double>(),
           py::arg("model"), py::arg("tool_frame"), py::arg("stiffness"), py::arg("damping"),
           py::arg("k_null"), py::arg("d_null"), py::arg("d_joint"))
      .def("kinematics", &ImpedanceKernel::kinematics)
      .def("set_reference", &ImpedanceKernel::set_reference)
      .def("set_posture", &ImpedanceKernel::set_posture)
      .def("set_gains", &ImpedanceKernel::set_gains)
      .def("step", &ImpedanceKernel::step);
}
