// The planner server's request handling (server::PlannerServer::answer(): the bytes of one
// connection through a socket pair, as a client's would come): the request line and path, the
// headers (Host, Origin, the token, Content-Length, chunked framing, cookies), the body and its
// JSON, every route. "{HOST}" and "{TOKEN}" in the input become the server's own, so that the
// fuzzer reaches the routes behind the screen. The answer must be HTTP with a JSON error body for
// every refusal; a crash, a hang, a sanitizer report or an exception escaping is a finding.
#include "caps/app/model.hpp"
#include "caps/server/planner_server.hpp"
#include "fuzz_input.hpp"

#include <cstdlib>
#include <iostream>
#include <memory>

namespace {

std::string replace_all(std::string text, const std::string& from, const std::string& to) {
  for (std::size_t at = 0; (at = text.find(from, at)) != std::string::npos; at += to.size())
    text.replace(at, from.size(), to);
  return text;
}

// A server on the phantom's model (built once, into the fuzzer's work folder), never listening:
// each input is served through answer().
caps::server::PlannerServer& server() {
  static const std::unique_ptr<caps::server::PlannerServer> s = [] {
    const caps_fuzz::fs::path dir = caps_fuzz::fs::temp_directory_path() /
                                    ("caps_fuzz_server_" + std::to_string(::getpid()));
    caps_fuzz::fs::create_directories(dir);
    caps::app::PhantomRequest ph;
    ph.output = (dir / "ct.nii.gz").string();
    ph.voxels = "96,96,90";
    ph.spacing = "2.5,2.5,2.5";
    caps::app::run_phantom(ph);
    caps::app::FromVolumeRequest fv;
    fv.input = ph.output;
    fv.output = (dir / "model").string();
    fv.n_theta = 64;
    fv.n_z = 32;
    // Without the whole-face tissue model: OpenVDB's accessor registry (a TBB concurrent hash
    // map) trips UBSan's alignment check while the level sets are built, in the libraries.
    fv.no_tissue = true;
    caps::app::run_from_volume(fv);
    std::ofstream(dir / "index.html") << "<!doctype html><html><head></head><body></body></html>";
    caps::server::ServerOptions o;
    o.model_dir = fv.output;
    o.port = 8765;  // never bound: the Host the screen expects
    o.web_root = dir.string();
    o.header_timeout_s = 1;
    std::atexit([] {
      std::error_code ec;
      caps_fuzz::fs::remove_all(caps_fuzz::fs::temp_directory_path() /
                                    ("caps_fuzz_server_" + std::to_string(::getpid())),
                                ec);
    });
    return std::make_unique<caps::server::PlannerServer>(o);
  }();
  return *s;
}

}  // namespace

// The model is built before the first input (libFuzzer's time limit is per input).
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)server();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  caps::server::PlannerServer& s = server();
  std::string request(reinterpret_cast<const char*>(data), size);
  request = replace_all(std::move(request), "{HOST}", "127.0.0.1:8765");
  request = replace_all(std::move(request), "{TOKEN}", s.token());
  const std::string answer = s.answer(request);
  // Whatever came in, what goes out is HTTP (or nothing, for a connection closed unanswered).
  if (!answer.empty() && answer.rfind("HTTP/1.1 ", 0) != 0) {
    std::cerr << "fuzz_server: an answer that is not HTTP: " << answer.substr(0, 80) << "\n";
    std::abort();
  }
  return 0;
}
