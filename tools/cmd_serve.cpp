// caps serve: bound to server/ (caps/server/serve.hpp); docs/planner.md describes the API.
//   caps serve /tmp/cranium
//   caps serve /tmp/cranium --port 0
//   caps serve /tmp/cranium --port 8080 --web-root my-page/  (default: the page built into build/web/dist)
#include "caps/server/serve.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_serve(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "serve",
           "Serve the planner (the page and its JSON API) on a patient model, on 127.0.0.1 until "
           "Ctrl-C.\nExample: caps serve cranium --port 8765, then open http://127.0.0.1:8765/",
           &server::run_serve, common, action);
}

}  // namespace caps::cli
