// The Python module caps._caps: a binding over the app:: requests and results (docs/python.md).
// Every verb of app's list (caps/app/verbs.hpp) is run from its request's JSON
// (app::read_request) and answers its result's JSON (app::to_json), so Python takes the same keys, defaults and checks as the command line and the
// planner's server. Besides the verbs, two readers hand a model's maps and a simulation's result
// to numpy. The Python side (python/caps/__init__.py) wraps these in keyword functions.
//
//   import caps
//   caps.run("phantom", {"output": "ct.nii.gz", "voxels": "96,96,90", "spacing": "2.5,2.5,2.5"})
//   caps.load_model("model")["thickness"].shape   # (n_z, n_theta)

#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "caps/app/verbs.hpp"
#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/fem/blas.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/volume/model_dir.hpp"

namespace py = pybind11;
using namespace caps;

namespace {

// ---- the reporter ------------------------------------------------------------------------

// Forwards warnings to Python's warnings.warn (category caps.CapsWarning) and progress to an
// optional callable(step, fraction). Calls may come from worker threads: each takes the GIL.
// A Python exception raised by either (a warnings filter set to "error", a callback that raises)
// is kept, the run is cancelled at its next progress point, and the exception is raised again
// once the run has stopped.
class PythonReporter : public Reporter {
 public:
  PythonReporter(py::object warning_category, py::object progress)
      : category_(std::move(warning_category)), progress_(std::move(progress)) {}
  ~PythonReporter() override {
    py::gil_scoped_acquire gil;
    category_ = py::object();
    progress_ = py::object();
  }

  bool is_cancelled() const override { return failed_.load(); }

  /// Raises the Python exception a callback raised, if any (call with the GIL held).
  void rethrow() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (error_) {
      auto e = std::move(error_);
      e->restore();
      throw py::error_already_set();
    }
  }

 protected:
  void on_warning(const std::string& message) override {
    call([&] {
      py::module_::import("warnings").attr("warn")(message, category_, 2);
    });
  }
  void on_progress(const std::string& step, double fraction) override {
    if (!progress_.is_none()) call([&] { progress_(step, fraction); });
  }
  void on_step_done(const std::string& step) override {
    if (!progress_.is_none()) call([&] { progress_(step, 1.0); });
  }

 private:
  template <class F>
  void call(F&& f) {
    if (failed_.load()) return;
    py::gil_scoped_acquire gil;
    try {
      f();
    } catch (py::error_already_set& e) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::make_unique<py::error_already_set>(std::move(e));
      failed_ = true;
    }
  }

  py::object category_, progress_;
  std::atomic<bool> failed_{false};
  std::mutex mutex_;
  std::unique_ptr<py::error_already_set> error_;
};

// ---- the verbs ---------------------------------------------------------------------------

// Every verb of app's list (caps/app/verbs.hpp). Python's names are the command line's words
// joined by "_" ("model from-volume" -> "model_from_volume"); the command line's spelling is
// accepted too.
std::vector<std::string> verb_names() {
  std::vector<std::string> names;
  for (const app::VerbEntry& v : app::verbs()) names.push_back(v.key);
  return names;
}

// ---- errors ------------------------------------------------------------------------------

// The Python classes of the caps errors, set once by caps/__init__.py (_set_exceptions).
py::dict& exception_classes() {
  static py::dict* classes = new py::dict();  // never freed: lives as long as the interpreter
  return *classes;
}

void raise(const char* kind, const std::string& message) {
  py::object cls = exception_classes().contains(kind)
                       ? py::object(exception_classes()[kind])
                       : py::reinterpret_borrow<py::object>(PyExc_RuntimeError);
  PyErr_SetObject(cls.ptr(), py::str(message).ptr());
}

void translate(std::exception_ptr p) {
  try {
    if (p) std::rethrow_exception(p);
  } catch (const InvalidParameter& e) {
    raise("InvalidParameter", e.what());
  } catch (const InvalidInput& e) {
    raise("InvalidInput", e.what());
  } catch (const IoError& e) {
    raise("IoError", e.what());
  } catch (const SolverError& e) {
    raise("SolverError", e.what());
    // where it failed, as attributes of the raised exception
    py::error_already_set err;
    py::object value = err.value();
    value.attr("element") = e.element;
    value.attr("gauss_point") = e.gauss_point;
    value.attr("iteration") = e.iteration;
    err.restore();
  } catch (const Cancelled& e) {
    raise("Cancelled", e.what());
  } catch (const Error& e) {
    raise("Error", e.what());
  }
}

// Runs a verb with the GIL released; errors a callback raised come back as they were.
std::string run_verb(const std::string& name, const std::string& request_json,
                     const std::string& source, py::object warning_category,
                     py::object progress) {
  const app::VerbEntry& v = app::find_verb(name);
  PythonReporter reporter(std::move(warning_category), std::move(progress));
  std::string result;
  try {
    py::gil_scoped_release release;
    result = v.run_json(request_json, source, &reporter);
  } catch (const Cancelled&) {
    reporter.rethrow();
    throw;
  }
  reporter.rethrow();
  return result;
}

// ---- numpy views -------------------------------------------------------------------------

// A numpy array owning `values` (moved, not copied), of the given shape, row-major.
template <class T>
py::array_t<T> owned_array(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* heap = new std::vector<T>(std::move(values));
  py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, heap->data(), owner);
}

py::dict load_model(const std::string& dir) {
  ModelInfo info;
  CylindricalMaps maps;
  {
    py::gil_scoped_release release;
    info = read_model_info(dir);
    maps = read_model_maps(dir, info);
  }
  const CylinderGrid& g = maps.grid;
  const std::vector<py::ssize_t> shape = {g.n_z, g.n_theta};  // theta fastest: rows are z
  Eigen::VectorXd theta(g.n_theta), z(g.n_z);
  for (int j = 0; j < g.n_theta; ++j) theta[j] = g.theta_deg(j);
  for (int k = 0; k < g.n_z; ++k) z[k] = g.z_mm(k);
  std::vector<std::uint8_t> valid(maps.flags.size());
  for (std::size_t i = 0; i < valid.size(); ++i) valid[i] = flags_valid(maps.flags[i]);

  py::dict axis;
  axis["origin_lps"] = Eigen::Vector3d(maps.axis.origin_lps);
  axis["direction"] = Eigen::Vector3d(maps.axis.direction);
  axis["front"] = Eigen::Vector3d(maps.axis.front);

  py::dict d;
  d["model_json"] = read_model_json(dir);
  d["theta_deg"] = theta;
  d["z_mm"] = z;
  d["axis"] = axis;
  d["r_skin"] = owned_array(std::move(maps.r_skin), shape);
  d["r_bone"] = owned_array(std::move(maps.r_bone), shape);
  d["thickness"] = owned_array(std::move(maps.thickness), shape);
  d["thickness_normal"] = owned_array(std::move(maps.thickness_normal), shape);
  d["flags"] = owned_array(std::move(maps.flags), shape);
  d["valid"] = py::array_t<bool>(owned_array(std::move(valid), shape));
  d["measured_skin"] = py::array_t<bool>(owned_array(std::move(maps.measured_skin), shape));
  d["measured_bone"] = py::array_t<bool>(owned_array(std::move(maps.measured_bone), shape));
  // model.json's "landmarks" (docs/landmarks.md): {name: {found, theta_deg, z_mm, lps, ...}},
  // or None for a model built before landmarks existed (caps.run("model landmarks", ...)).
  if (info.landmarks_json.empty())
    d["landmarks"] = py::none();
  else
    d["landmarks"] = py::module_::import("json").attr("loads")(info.landmarks_json)["items"];
  return d;
}

py::dict read_result(const std::string& dir) {
  fem::Mesh mesh;
  Eigen::MatrixX3d u;
  Eigen::VectorXd s1;
  {
    py::gil_scoped_release release;
    mesh = fem::read_mesh_dir(dir);
    u = fem::read_result_displacement(dir, mesh.n_nodes());
    s1 = fem::read_result_max_principal(dir, mesh.n_nodes());
  }
  py::dict d;
  d["nodes"] = std::move(mesh.nodes);
  d["displacement"] = std::move(u);
  d["max_principal_mpa"] = std::move(s1);
  return d;
}

}  // namespace

PYBIND11_MODULE(_caps, m) {
  m.doc() = "caps: the app:: requests and results (see docs/python.md); use the package caps.";
  // OpenBLAS's generic kernels on a CPU it does not know: the CPU's own (fem/blas.hpp), as the
  // caps program does at its start.
  caps::fem::use_the_cpus_blas_kernels();

  py::register_exception_translator(&translate);

  m.def(
      "_set_exceptions", [](py::dict classes) { exception_classes() = classes; },
      "Sets the Python classes raised for the caps error kinds (by caps/__init__.py).");

  m.def("run_json", &run_verb, py::arg("verb"), py::arg("request_json"),
        py::arg("source") = "request", py::arg("warning_category") = py::none(),
        py::arg("progress") = py::none(),
        "Runs a verb on its request as JSON text (app::read_request) and returns its result as "
        "JSON text (app::to_json). Warnings go to warnings.warn(message, warning_category); "
        "progress to progress(step, fraction in 0..1).");

  m.def(
      "defaults_json", [](const std::string& name) { return app::find_verb(name).defaults_json(); },
      py::arg("verb"), "Every field of a verb's request with its default, as JSON text.");

  m.def("verbs", &verb_names,
        "The verb names run_json() accepts: every verb of the caps program (app's list), in its "
        "order.");

  m.def(
      "command_line_names",
      [] {
        std::vector<std::string> names;
        for (const app::VerbEntry& v : app::verbs()) names.push_back(v.name);
        return names;
      },
      "The same verbs as verbs(), spelled as the command line's words (\"model from-volume\").");

  m.def(
      "verb_help", [](const std::string& name) { return std::string(app::find_verb(name).help); },
      py::arg("verb"), "A verb's help, as `caps <verb> --help` prints it.");

  m.def("load_model", &load_model, py::arg("model_dir"),
        "A model directory's model.json (text) and maps: numpy arrays of shape (n_z, n_theta), "
        "row k at z_mm[k], column j at theta_deg[j]: r_skin, r_bone, thickness, "
        "thickness_normal (float32, mm), flags (uint8, 0 = valid), valid, measured_skin, "
        "measured_bone (bool); the axis (LPS mm); landmarks: model.json's landmarks by name "
        "(found, theta_deg, z_mm, lps, confidence, thickness_mm, note) or None.");

  m.def("read_result", &read_result, py::arg("result_dir"),
        "A solve's or simulation's result directory: nodes (#N x 3, LPS mm), displacement "
        "(#N x 3, mm), max_principal_mpa (#N, MPa).");
}
