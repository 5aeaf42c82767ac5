#include "caps/server/serve.hpp"

#include "caps/core/error.hpp"

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <sstream>
#include <thread>

namespace caps::server {

namespace {

std::atomic<int> g_signal{0};

// A second signal while stopping ends the program at once (the default action).
extern "C" void on_stop_signal(int signal) {
  g_signal = signal;
  std::signal(signal, SIG_DFL);
}

// Installs SIGINT/SIGTERM handlers for its lifetime and restores the previous ones after.
class StopSignals {
 public:
  StopSignals()
      : old_int_(std::signal(SIGINT, on_stop_signal)),
        old_term_(std::signal(SIGTERM, on_stop_signal)) {
    g_signal = 0;
  }
  ~StopSignals() {
    std::signal(SIGINT, old_int_);
    std::signal(SIGTERM, old_term_);
  }

 private:
  void (*old_int_)(int);
  void (*old_term_)(int);
};

}  // namespace

ServeResult run_serve(const ServeRequest& r, Reporter* reporter) {
  ServerOptions o;
  o.model_dir = r.model;
  o.host = r.host;
  o.port = r.port;
  o.web_root = r.web_root;
  std::istringstream names(r.allow_host);
  for (std::string name; std::getline(names, name, ',');) o.allowed_hosts.push_back(name);
  PlannerServer server(o, reporter);
  server.bind();
  note(reporter, cat("the planner for ", r.model, " is at ", server.url(), " (Ctrl-C stops it)"));
  StopSignals signals;
  std::atomic<bool> done{false};
  // A signal handler may only set a flag; this thread turns the flag into stop(), which cancels
  // a running simulation and closes the connections (within a second); the work folder goes
  // with the server.
  std::thread watcher([&] {
    while (!done) {
      const int signal = g_signal.load();
      if (signal || (reporter && reporter->is_cancelled())) {
        note(reporter, cat("caps serve: ", signal == SIGINT ? "SIGINT" : signal == SIGTERM ? "SIGTERM" : "cancelled",
                           ": stopping (a running simulation is cancelled, the work folder removed)"));
        server.stop();
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  server.listen();
  done = true;
  watcher.join();
  return {server.url(), server.n_requests()};
}

std::string to_json(const ServeResult& r) {
  return nlohmann::json{{"url", r.url}, {"requests", r.requests}}.dump(2);
}

std::string summary(const ServeResult& r) {
  return cat("caps serve: stopped after ", r.requests, " requests at ", r.url);
}

}  // namespace caps::server
