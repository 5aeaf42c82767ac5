#include "caps/app/run_guard.hpp"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

namespace caps::app {
namespace {

// The pipe the handler writes to; -1 when no InterruptCleanup lives.
volatile sig_atomic_t g_pipe_write = -1;

extern "C" void on_signal(int sig) {
  const int saved = errno;
  const int fd = g_pipe_write;
  if (fd >= 0) {
    const unsigned char b = static_cast<unsigned char>(sig);
    [[maybe_unused]] const ssize_t n = ::write(fd, &b, 1);  // async-signal-safe
  }
  errno = saved;
}

constexpr int kSignals[] = {SIGINT, SIGTERM, SIGHUP};

const char* signal_name(int sig) {
  switch (sig) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
  }
  return "a signal";
}

}  // namespace

struct InterruptCleanup::State {
  int fds[2] = {-1, -1};
  struct sigaction old[3] {};
  std::thread watcher;
};

InterruptCleanup::InterruptCleanup() : state_(std::make_unique<State>()) {
  State& s = *state_;
  if (::pipe2(s.fds, O_CLOEXEC) != 0) return;  // no cleanup on signals, but the run goes on
  g_pipe_write = s.fds[1];
  s.watcher = std::thread([read_fd = s.fds[0]] {
    unsigned char sig = 0;
    for (;;) {
      const ssize_t n = ::read(read_fd, &sig, 1);
      if (n < 0 && errno == EINTR) continue;
      if (n != 1 || sig == 0) return;  // closed or told to stop
      const std::vector<std::string> outputs = abandon_unfinished_outputs();
      std::string message = std::string("\ncaps: interrupted by ") + signal_name(sig);
      if (outputs.empty()) {
        message += "\n";
      } else {
        message += "; nothing was written to ";
        for (std::size_t i = 0; i < outputs.size(); ++i)
          message += (i ? ", " : "") + outputs[i];
        message += " (the unfinished output was removed)\n";
      }
      [[maybe_unused]] const ssize_t w = ::write(STDERR_FILENO, message.data(), message.size());
      ::_exit(128 + sig);
    }
  });
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  for (int i = 0; i < 3; ++i) ::sigaction(kSignals[i], &sa, &s.old[i]);
}

InterruptCleanup::~InterruptCleanup() {
  State& s = *state_;
  if (s.fds[1] < 0) return;
  for (int i = 0; i < 3; ++i) ::sigaction(kSignals[i], &s.old[i], nullptr);
  g_pipe_write = -1;
  const unsigned char stop = 0;
  [[maybe_unused]] const ssize_t n = ::write(s.fds[1], &stop, 1);
  if (s.watcher.joinable()) s.watcher.join();
  ::close(s.fds[0]);
  ::close(s.fds[1]);
}

}  // namespace caps::app
