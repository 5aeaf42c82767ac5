#include "caps/core/crash_report.hpp"

#include <execinfo.h>
#include <signal.h>
#include <unistd.h>

#include <cstring>
#include <initializer_list>

namespace caps {
namespace {

// Only async-signal-safe calls here (write, backtrace_symbols_fd; backtrace() itself is loaded
// before any fault, below).
void write_text(const char* s) {
  const ssize_t ignored = ::write(STDERR_FILENO, s, std::strlen(s));
  (void)ignored;
}

extern "C" void on_fault(int signal_number) {
  write_text("\ncaps: internal error: ");
  write_text(signal_number == SIGFPE    ? "arithmetic fault (SIGFPE)"
             : signal_number == SIGSEGV ? "invalid memory access (SIGSEGV)"
             : signal_number == SIGBUS  ? "bus error (SIGBUS)"
                                        : "illegal instruction (SIGILL)");
  write_text("; please report it with this call stack:\n");
  void* frames[64];
  const int n = ::backtrace(frames, 64);
  ::backtrace_symbols_fd(frames, n, STDERR_FILENO);
  // SA_RESETHAND restored the default action: the same signal ends the process.
  ::raise(signal_number);
}

}  // namespace

void install_crash_report() {
#if defined(__SANITIZE_ADDRESS__)
  return;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
  return;
#endif
#endif
  static const bool installed = [] {
    void* warm[1];
    ::backtrace(warm, 1);  // loads libgcc's unwinder now, not inside the handler
    struct sigaction a {};
    a.sa_handler = on_fault;
    sigemptyset(&a.sa_mask);
    a.sa_flags = SA_RESETHAND | SA_NODEFER;
    for (int s : {SIGFPE, SIGSEGV, SIGBUS, SIGILL}) ::sigaction(s, &a, nullptr);
    return true;
  }();
  (void)installed;
}

}  // namespace caps
