#pragma once
/// @brief What a front end holds while a verb runs: the claim on the request's output (a second
/// run writing it is refused; --force replaces only a regular file or a folder caps wrote), and,
/// for the command line, the removal of unfinished outputs on SIGINT, SIGTERM or SIGHUP.

#include <memory>
#include <string>
#include <type_traits>

#include "caps/app/fields.hpp"
#include "caps/core/atomic_output.hpp"

namespace caps::app {

namespace detail {
// Finds a request's "output" and "force" fields.
struct OutputFields {
  const std::string* output = nullptr;
  bool force = false;
  template <class T>
  void operator()(const T& value, const Field& f) {
    if constexpr (std::is_same_v<T, std::string>) {
      if (f.key == "output") output = &value;
    } else if constexpr (std::is_same_v<T, bool>) {
      if (f.key == "force") force = value;
    }
  }
};
}  // namespace detail

/// Claims the request's output (its "output" field, with its "force") for the run: nullptr for a
/// verb without an output. Throws InvalidInput when another run holds it or when --force would
/// replace something caps may not (a device, a FIFO, a symbolic link, a folder it did not write).
template <class Request>
std::unique_ptr<OutputClaim> claim_output(const Request& request) {
  detail::OutputFields f;
  Request::fields(request, f);
  if (!f.output || f.output->empty()) return nullptr;
  return std::make_unique<OutputClaim>(*f.output, f.force);
}

/// While it lives, SIGINT, SIGTERM and SIGHUP end the process after removing this process's
/// unfinished outputs (their temporaries and claims: abandon_unfinished_outputs()), with a message
/// on stderr and the exit code 128 + the signal's number (130, 143, 129). The handler only writes
/// the signal's number to a pipe; a thread of this object's does the removal. One at a time.
class InterruptCleanup {
 public:
  InterruptCleanup();
  ~InterruptCleanup();
  InterruptCleanup(const InterruptCleanup&) = delete;
  InterruptCleanup& operator=(const InterruptCleanup&) = delete;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace caps::app
