#pragma once
/// @brief `caps serve` as a request and a result (the app:: style, fields declared once).

#include <string>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"
#include "caps/server/planner_server.hpp"

namespace caps::server {

struct ServeRequest {
  std::string model;
  int port = kDefaultPort;
  std::string host = kDefaultHost;
  std::string web_root;
  std::string allow_host;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    using app::FieldKind;
    v(r.model, {"model", "the patient model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.port, {"port", "the TCP port to listen on (0: any free one)"});
    v(r.host, {"host",
               "the address to bind; anything but 127.0.0.1 lets other machines use the "
               "planner and read the model (a warning is printed)"});
    v(r.web_root, {"web_root",
                   "serve the page from this folder (default: the page the build bundled, "
                   "build/web/dist, else a placeholder page)"});
    v(r.allow_host, {"allow_host",
                     "with --host other than 127.0.0.1: the names or addresses other machines "
                     "open the planner by (comma-separated, e.g. planner.clinic.local,192.168.1.20); "
                     "a request addressed to any other name is refused (403)"});
  }
};

struct ServeResult {
  std::string url;
  long requests = 0;
};

/// Serves the planner on the model until SIGINT or SIGTERM (or the reporter cancels); notes the
/// URL to open through the reporter once listening.
ServeResult run_serve(const ServeRequest& request, Reporter* reporter = nullptr);
std::string to_json(const ServeResult& result);
std::string summary(const ServeResult& result);

}  // namespace caps::server
