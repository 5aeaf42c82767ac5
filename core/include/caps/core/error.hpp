#pragma once
/// @brief caps error types, the cat() message builder and CAPS_ASSERT.
///
/// Library code throws and never aborts. Messages say what failed, where, the offending value and
/// what to do next. The CLI maps InvalidInput and IoError to exit code 2, anything else to 1.

#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>

namespace caps {

/// Base of every caps error.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A file could not be read or written (missing, truncated, unreadable, unwritable).
class IoError : public Error {
 public:
  using Error::Error;
};

/// The input is readable but not acceptable (bad values, wrong shape, out of range).
class InvalidInput : public Error {
 public:
  using Error::Error;
};

/// Invalid input in named parameters. The message is a template in which each parameter's name
/// stands in braces ("ellipse: give {width} or {apex_angle}, not both"); what() shows the names
/// as they are (JSON keys), spelled() as a front end's user typed them (--apex-angle).
class InvalidParameter : public InvalidInput {
 public:
  explicit InvalidParameter(const std::string& message_template);
  /// The message with every {name} replaced by spell(name).
  std::string spelled(const std::function<std::string(const std::string&)>& spell) const;

 private:
  std::string template_;
};

/// A numerical solve failed; carries where it failed (-1 where not known) and names it at the
/// start of what(): "element 3, Gauss point 0: Jacobian determinant ...".
class SolverError : public Error {
 public:
  SolverError(const std::string& what, int element = -1, int gauss_point = -1, int iteration = -1);
  int element;      ///< index into Mesh::elements, -1 if not known
  int gauss_point;  ///< Gauss point of that element (its quadrature order), -1 if not known
  int iteration;    ///< iteration of an iterative refinement (0: its start), -1 if not known
};

/// Streams all arguments into one string: cat("spacing ", 0.5, " mm").
template <typename... Args>
std::string cat(const Args&... args) {
  std::ostringstream os;
  (os << ... << args);
  return os.str();
}

namespace detail {
[[noreturn]] void assertion_failed(const char* cond, const std::string& msg, const char* file,
                                   int line);
}

}  // namespace caps

#ifdef NDEBUG
#define CAPS_ASSERT(cond, msg) ((void)0)
#else
#define CAPS_ASSERT(cond, msg) \
  ((cond) ? (void)0 : ::caps::detail::assertion_failed(#cond, (msg), __FILE__, __LINE__))
#endif
