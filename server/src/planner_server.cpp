#include "caps/server/planner_server.hpp"

#include "caps/app/loaded_model.hpp"
#include "caps/app/verbs.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/surface/patient_model.hpp"
#include "guarded_http.hpp"
#include "page_words.hpp"
#include "skin_views.hpp"

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

namespace caps::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// A refusal with its HTTP status (403, 404, ...) that is no caps error kind of its own.
class Refusal : public Error {
 public:
  Refusal(int status, const std::string& message) : Error(message), status(status) {}
  int status;
};

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(cat(path.string(), ": cannot read"));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string content_type(const fs::path& path) {
  static const std::map<std::string, std::string> kTypes = {
      {".html", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".json", "application/json"},
      {".map", "application/json"},
      {".png", "image/png"},
      {".jpg", "image/jpeg"},
      {".jpeg", "image/jpeg"},
      {".gif", "image/gif"},
      {".svg", "image/svg+xml"},
      {".ico", "image/x-icon"},
      {".txt", "text/plain; charset=utf-8"},
      {".wasm", "application/wasm"},
      {".glb", "model/gltf-binary"},
      {".gltf", "model/gltf+json"},
      {".vtu", "application/xml"},
      {".ply", "application/octet-stream"},
      {".woff2", "font/woff2"}};
  const auto it = kTypes.find(path.extension().string());
  return it == kTypes.end() ? "application/octet-stream" : it->second;
}

// The regular file `relative` (a request's decoded path, '/'-separated) inside `root`, after
// symbolic links are resolved; 403 for a path that leaves the root, 404 for no such file.
fs::path file_under(const fs::path& root, const std::string& relative) {
  if (relative.find('\0') != std::string::npos || relative.find('\\') != std::string::npos)
    throw Refusal(403, cat("\"", relative, "\": not a path the server serves"));
  const fs::path rel = fs::path(relative).relative_path();
  for (const fs::path& part : rel)
    if (part == "..") throw Refusal(403, cat("\"", relative, "\": leaves the served folder"));
  std::error_code ec;
  const fs::path base = fs::weakly_canonical(root, ec);
  const fs::path full = fs::weakly_canonical(base / rel, ec);
  if (ec) throw Refusal(404, cat("\"", relative, "\": no such file"));
  const auto [b, f] = std::mismatch(base.begin(), base.end(), full.begin(), full.end());
  if (b != base.end()) throw Refusal(403, cat("\"", relative, "\": leaves the served folder"));
  if (!fs::is_regular_file(full)) throw Refusal(404, cat("\"", relative, "\": no such file"));
  return full;
}

// The plan's name for messages: the request's `name` query parameter when it is a plain file
// name ending in .json (the page sends the name of the file loaded), else "plan.json".
std::string plan_name(const httplib::Request& req) {
  const std::string name = req.get_param_value("name");
  const bool plain =
      !name.empty() && name.size() <= 128 && name.front() != '.' &&
      std::all_of(name.begin(), name.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-';
      });
  return plain && fs::path(name).extension() == ".json" ? name : "plan.json";
}

void send_file(httplib::Response& res, const fs::path& path) {
  res.set_content(read_file(path), content_type(path).c_str());
}

void send_json(httplib::Response& res, const std::string& text) {
  res.set_content(text, "application/json");
}

// {"error": message}; bytes of the message that are not UTF-8 (a request's path or body quoted
// back) are replaced, so that the refusal itself cannot fail.
void send_error(httplib::Response& res, int status, const std::string& message) {
  res.status = status;
  json body = json::object();
  body["error"] = message;
  send_json(res, body.dump(-1, ' ', false, json::error_handler_t::replace));
}

// 128 random bits as hex: the session's token.
std::string random_token() {
  std::random_device device;  // the kernel's random source (getrandom) on Linux
  std::string token;
  for (int i = 0; i < 4; ++i) {
    char part[9];
    std::snprintf(part, sizeof(part), "%08x", static_cast<unsigned>(device()));
    token += part;
  }
  return token;
}

// Compares in time independent of where the texts differ (the token).
bool same_secret(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d |= static_cast<unsigned char>(a[i] ^ b[i]);
  return d == 0;
}

std::string lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// The value of the cookie `name` in the request's Cookie header, or "".
std::string cookie(const httplib::Request& req, const std::string& name) {
  const std::string header = req.get_header_value("Cookie");
  std::size_t at = 0;
  while (at < header.size()) {
    std::size_t end = header.find(';', at);
    if (end == std::string::npos) end = header.size();
    std::size_t begin = at;
    while (begin < end && header[begin] == ' ') ++begin;
    const std::size_t eq = header.find('=', begin);
    if (eq != std::string::npos && eq < end && header.compare(begin, eq - begin, name) == 0)
      return header.substr(eq + 1, end - eq - 1);
    at = end + 1;
  }
  return "";
}

// Work folders of servers that ended without removing theirs (killed, crashed): the temporary
// directory's caps-serve-<pid>-<n> whose process is gone.
void remove_stale_work_dirs() {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(fs::temp_directory_path(), ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("caps-serve-", 0) != 0) continue;
    const long pid = std::strtol(name.c_str() + 11, nullptr, 10);
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    std::error_code ignored;
    fs::remove_all(entry.path(), ignored);
  }
}

json parse_object(const std::string& body, const std::string& source) {
  const json j = parse_json<json>(body, source);
  if (!j.is_object()) throw InvalidInput(cat(source, ": expected a JSON object"));
  return j;
}

// Keys the server fills itself (its model, its work folder) are refused, naming them.
void refuse_server_keys(const json& j, std::initializer_list<const char*> keys,
                        const std::string& source) {
  for (const char* k : keys)
    if (j.contains(k))
      throw InvalidInput(cat(source, ": \"", k,
                             "\" is set by the server (its model and work "
                             "folder); leave it out"));
}

// Cancels a simulation once a newer simulate request has come; passes progress and warnings on.
class SimulationReporter : public Reporter {
 public:
  SimulationReporter(const std::atomic<std::uint64_t>& latest, std::uint64_t ticket,
                     const std::atomic<bool>& stopping, Reporter* outer)
      : latest_(latest), ticket_(ticket), stopping_(stopping), outer_(outer) {}
  bool is_cancelled() const override { return latest_.load() != ticket_ || stopping_.load(); }

 protected:
  void on_warning(const std::string& m) override { caps::warn(outer_, m); }
  void on_note(const std::string& m) override { caps::note(outer_, m); }
  // A cancelled simulation's last steps, until its next check, are not shown.
  void on_progress(const std::string& step, double fraction) override {
    if (outer_ && !is_cancelled()) outer_->progress(step, fraction);
  }
  void on_step_done(const std::string& step) override {
    if (outer_ && !is_cancelled()) outer_->step_done(step);
  }

 private:
  const std::atomic<std::uint64_t>& latest_;  // not owned; the server's, outlives this
  std::uint64_t ticket_;
  const std::atomic<bool>& stopping_;  // not owned; the server's, outlives this
  Reporter* outer_;  // not owned; may be null
};

// The running simulation's progress as the page polls it (GET /api/progress); passes everything on.
class ProgressBoard : public Reporter {
 public:
  explicit ProgressBoard(Reporter* outer) : outer_(outer) {}
  void start() {
    set("starting", 0, true);
    std::lock_guard<std::mutex> lock(m_);
    steps_s_ = json::object();
    step_started_ = started_;
    first_answer_ = nullptr;
  }
  /// The running request's first answer (the linear closure's result, with its result_id),
  /// shown by the page while the finite-strain closure runs; kept until the next start().
  void set_first_answer(json result) {
    std::lock_guard<std::mutex> lock(m_);
    first_answer_ = std::move(result);
  }
  void finish() { set("", 1, false); }
  /// The running request was cancelled and answered: not running any more for the page, while
  /// its work stops at its next check (run_cancellable) and then finishes the board.
  void cancel() {
    bool was_running = false;
    {
      std::lock_guard<std::mutex> lock(m_);
      was_running = running_;
    }
    if (was_running) set("stopping the cancelled simulation", 0, false);
  }
  /// Seconds spent in each progress step of the last simulation ({"meshing and solving": ...}).
  json steps_s() const {
    std::lock_guard<std::mutex> lock(m_);
    return steps_s_;
  }
  json snapshot() const {
    std::lock_guard<std::mutex> lock(m_);
    json j{{"running", running_}, {"step", step_}, {"fraction", fraction_},
           {"elapsed_s", running_ ? std::chrono::duration<double>(
                                        std::chrono::steady_clock::now() - started_)
                                        .count()
                                  : 0.0}};
    if (!first_answer_.is_null()) j["first_answer"] = first_answer_;
    return j;
  }

 protected:
  void on_warning(const std::string& m) override { caps::warn(outer_, m); }
  void on_note(const std::string& m) override { caps::note(outer_, m); }
  void on_progress(const std::string& step, double fraction) override {
    set(step, fraction, true);
    if (outer_) outer_->progress(step, fraction);
  }
  void on_step_done(const std::string& step) override {
    if (outer_) outer_->step_done(step);
  }

 private:
  void set(const std::string& step, double fraction, bool running) {
    std::lock_guard<std::mutex> lock(m_);
    const auto now = std::chrono::steady_clock::now();
    if (running && !running_) started_ = now;
    if (step != step_ && !step_.empty() && step_ != "starting")
      steps_s_[step_] =
          steps_s_.value(step_, 0.0) + std::chrono::duration<double>(now - step_started_).count();
    if (step != step_) step_started_ = now;
    step_ = step;
    fraction_ = fraction;
    running_ = running;
  }
  mutable std::mutex m_;
  std::string step_;
  double fraction_ = 0;
  bool running_ = false;
  std::chrono::steady_clock::time_point started_, step_started_;
  json steps_s_ = json::object();
  json first_answer_;  // null: none
  Reporter* outer_;  // not owned; may be null
};

// A fresh folder under the temporary directory for this server's plans and results.
fs::path make_work_dir() {
  static std::atomic<int> counter{0};
  const fs::path tmp = fs::temp_directory_path();
  for (int attempt = 0; attempt < 1000; ++attempt) {
    const fs::path dir = tmp / cat("caps-serve-", ::getpid(), "-", counter++);
    std::error_code ec;
    if (fs::create_directory(dir, ec)) {
      fs::create_directories(dir / "plans");
      fs::create_directories(dir / "results");
      return dir;
    }
  }
  throw IoError(cat(tmp.string(),
                    ": cannot create a work folder for the server; check that the "
                    "temporary directory is writable (TMPDIR)"));
}

}  // namespace

ErrorResponse error_response(const std::exception& e) {
  if (const auto* refusal = dynamic_cast<const Refusal*>(&e)) return {refusal->status, e.what()};
  // InvalidParameter (an InvalidInput) names its parameters as JSON keys in what().
  if (dynamic_cast<const InvalidInput*>(&e) || dynamic_cast<const IoError*>(&e))
    return {400, e.what()};
  if (dynamic_cast<const Cancelled*>(&e))
    return {409, "this simulation was cancelled by a newer simulate request, DELETE "
                 "/api/simulate or the server's stop"};
  if (dynamic_cast<const SolverError*>(&e)) return {422, e.what()};
  if (dynamic_cast<const std::bad_alloc*>(&e))
    return {500, "out of memory; the request may be larger than this machine can hold"};
  return {500, e.what()};
}

bool is_loopback(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

fs::path default_web_root() {
  // The page bundled by the build (the caps_web target): beside the program (build/tools/caps
  // -> build/web/dist), else where this build wrote it, else a bundle in the source tree.
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  std::vector<fs::path> candidates;
  if (!ec) candidates.push_back(exe.parent_path().parent_path() / "web" / "dist");
  candidates.push_back(fs::path(CAPS_WEB_DIST));
  const fs::path web(CAPS_WEB_DIR);
  candidates.push_back(web / "dist");
  for (const fs::path& dist : candidates)
    if (fs::is_regular_file(dist / "index.html")) return dist.lexically_normal();
  return web;
}

struct PlannerServer::Impl {
  ServerOptions options;
  Reporter* reporter;  // not owned; may be null
  fs::path work, web;
  bool placeholder = false;  // serving web/ itself: only its index.html
  detail::GuardedHttpServer http;
  int port = 0;
  std::string token = random_token();
  std::vector<std::string> allowed_hosts;  // lower case, with the port
  std::atomic<bool> listening{false}, stop_requested{false};
  std::atomic<long> n_requests{0};
  std::atomic<int> next_id{0};
  std::atomic<std::uint64_t> latest_simulation{0};
  std::mutex simulation_mutex;  // kMaxConcurrentSimulations = 1
  // The model the requests work on: the one the server was started with, or a local chart of it
  // made through POST /api/chart (docs/planner.md). Requests take a copy of the pointer, so a
  // switch does not change a request already running.
  struct Served {
    std::string dir;                            // absolute
    std::shared_ptr<const PatientModel> model;  // loaded once (app::loaded_model)
    int generation = 0;                         // its skin files: work/skin/<generation>/
  };
  std::shared_ptr<const Served> served, head;   // head: the model the server was started with
  std::mutex served_mutex;
  std::map<int, std::shared_ptr<const Served>> result_models;  // by result id (served_mutex)
  std::shared_ptr<const Served> current() {
    std::lock_guard<std::mutex> lock(served_mutex);
    return served;
  }
  std::unique_ptr<ProgressBoard> progress;

  // A simulate or suggest request's ticket: it makes the request the latest, so an older one
  // still running is cancelled (its reporter sees a newer ticket) and a newer one, DELETE
  // /api/simulate or the server's stop will cancel this. Passes progress on to the board.
  std::shared_ptr<SimulationReporter> new_ticket() {
    auto ticket = std::make_shared<SimulationReporter>(latest_simulation, ++latest_simulation,
                                                       stop_requested, progress.get());
    progress->cancel();  // the running one, if any
    return ticket;
  }

  // The simulation's slot, held by one simulate or suggest request at a time
  // (kMaxConcurrentSimulations = 1): waits for the running one to stop, then shows this one on
  // the progress board until released.
  class SimulationSlot {
   public:
    SimulationSlot(Impl& s, const SimulationReporter& ticket)
        : lock_(s.simulation_mutex), board_(*s.progress) {
      ticket.check_cancelled();  // a newer request came while this one waited
      board_.start();
    }
    ~SimulationSlot() { board_.finish(); }
    SimulationSlot(const SimulationSlot&) = delete;
    SimulationSlot& operator=(const SimulationSlot&) = delete;

   private:
    std::lock_guard<std::mutex> lock_;
    ProgressBoard& board_;
  };

  // Simulate and suggest run on a thread of their own while the request's thread waits for
  // their answer: a cancelled request (a newer one, DELETE /api/simulate, the server's stop) is
  // answered 409 within kCancelPollMs, while its work stops at its own next check, which can be
  // a factorization later (several seconds on a loaded machine: the hostile-input test saw 9 s).
  // The work holds the slot until it has stopped, so the next request still starts after it.
  static constexpr int kCancelPollMs = 20;
  std::mutex workers_mutex;
  std::condition_variable workers_done;
  int workers = 0;  // work threads still running (workers_mutex)

  std::string run_cancellable(const std::shared_ptr<SimulationReporter>& ticket,
                              std::function<std::string()> work) {
    auto answer = std::make_shared<std::promise<std::string>>();
    std::future<std::string> answered = answer->get_future();
    {
      std::lock_guard<std::mutex> lock(workers_mutex);
      ++workers;
    }
    std::thread([this, answer, work = std::move(work)] {
      try {
        answer->set_value(work());
      } catch (...) {
        answer->set_exception(std::current_exception());
      }
      // Notified under the lock: once it is released the server may be destroyed, and this
      // thread touches nothing of it any more.
      std::lock_guard<std::mutex> lock(workers_mutex);
      --workers;
      workers_done.notify_all();
    }).detach();
    while (answered.wait_for(std::chrono::milliseconds(kCancelPollMs)) != std::future_status::ready)
      ticket->check_cancelled();
    return answered.get();
  }

  void wait_for_workers() {
    std::unique_lock<std::mutex> lock(workers_mutex);
    workers_done.wait(lock, [this] { return workers == 0; });
  }
  std::mutex views_mutex;   // writing the skin's .glb files (once each)
  std::mutex export_mutex;  // rendering a result's export (once each)
  std::map<std::string, std::shared_future<void>> tension_files;  // by result id (views_mutex)

  Impl(ServerOptions o, Reporter* r)
      : options(std::move(o)), reporter(r), http(limits_of(options)) {}

  static detail::ConnectionLimits limits_of(const ServerOptions& o) {
    detail::ConnectionLimits l;
    l.header_timeout_s = o.header_timeout_s;
    l.min_bytes_per_s = o.min_bytes_per_s;
    l.max_connections = o.max_connections;
    l.max_body_bytes = o.max_body_bytes;
    return l;
  }

  // The Host values a request may carry: the address bound and the loopback names, with the
  // port (without it too on port 80, which browsers leave out).
  void set_allowed_hosts(int on_port) {
    std::vector<std::string> names = {options.host, "localhost", "127.0.0.1", "[::1]"};
    if (options.host.find(':') != std::string::npos) names[0] = "[" + options.host + "]";
    names.insert(names.end(), options.allowed_hosts.begin(), options.allowed_hosts.end());
    allowed_hosts.clear();
    for (const std::string& n : names) {
      allowed_hosts.push_back(lower(cat(n, ":", on_port)));
      if (on_port == 80) allowed_hosts.push_back(lower(n));
    }
  }

  // The refusal of a request that another site may have sent (docs/reliability.md): a Host not
  // the server's (DNS rebinding), an Origin not the server's on a request that is no GET (a
  // page elsewhere posting to it), an /api/ request without the session's token; or a path that
  // is not UTF-8. Checked before the body is read.
  std::optional<ErrorResponse> screen(const httplib::Request& req) const {
    const std::string host = lower(req.get_header_value("Host"));
    if (std::find(allowed_hosts.begin(), allowed_hosts.end(), host) == allowed_hosts.end())
      return ErrorResponse{403, "this server answers requests for its own address only (Host)"};
    const bool reads = req.method == "GET" || req.method == "HEAD";
    if (!reads && req.has_header("Origin")) {
      const std::string origin = lower(req.get_header_value("Origin"));
      const bool own = origin.rfind("http://", 0) == 0 &&
                       std::find(allowed_hosts.begin(), allowed_hosts.end(), origin.substr(7)) !=
                           allowed_hosts.end();
      if (!own) return ErrorResponse{403, "requests from other sites are refused (Origin)"};
    }
    if (first_invalid_utf8(req.path) != std::string_view::npos)
      return ErrorResponse{400, "the request's path is not valid UTF-8"};
    if (req.path.rfind("/api/", 0) == 0) {
      const std::string given = req.has_header(kTokenHeader) ? req.get_header_value(kTokenHeader)
                                : reads ? cookie(req, token_cookie())
                                        : std::string();
      if (!same_secret(given, token))
        return ErrorResponse{403, "the request lacks this session's token: reload the page "
                                  "(the server was restarted?)"};
    }
    return std::nullopt;
  }

  // The cookie of the token, per port: two servers on one machine keep their own.
  std::string token_cookie() const { return cat("caps_token_", port ? port : options.port); }

  using Route = std::function<void(const httplib::Request&, httplib::Response&)>;

  // Answers every error as {"error": message} with its status (error_response()).
  Route guarded(Route route) {
    return [this, route](const httplib::Request& req, httplib::Response& res) {
      ++n_requests;
      try {
        // Before anything reads the body or writes it into the work folder.
        if (const std::size_t bad = first_invalid_utf8(req.body); bad != std::string::npos)
          throw InvalidInput(cat("the request body is not valid UTF-8 (byte ", bad + 1, ")"));
        route(req, res);
      } catch (const std::exception& e) {
        const ErrorResponse error = error_response(e);
        send_error(res, error.status, page_words(without_work_dir(error.message)));
      }
    };
  }

  // `message` in the page's words (detail::page_words()) on the model served now.
  // An error's message is answered whatever happens to its rewording.
  std::string page_words(const std::string& message) {
    const std::shared_ptr<const Served> on = current();
    try {
      return on ? detail::page_words(message, *on->model, on->dir) : message;
    } catch (const std::exception&) {
      return message;
    }
  }

  // A verb's JSON answer with its warnings in the page's words (detail::page_words_json()).
  std::string in_page_words(const std::string& answer) {
    const std::shared_ptr<const Served> on = current();
    if (!on) return answer;
    json j = json::parse(answer);
    detail::page_words_json(j, *on->model, on->dir);
    return j.dump(2);
  }

  // A message as the command line gives it for the user's own file: the server's copies of request
  // bodies (work/plans/<n>/<name>) are named by their name alone, as `caps plan check <name>` run
  // in the file's folder names it, and no other path of the work folder is shown.
  std::string without_work_dir(std::string message) const {
    const std::string plans = (work / "plans").string() + "/", root = work.string() + "/";
    for (std::size_t at; (at = message.find(plans)) != std::string::npos;) {
      std::size_t end = at + plans.size();
      while (end < message.size() && std::isdigit(static_cast<unsigned char>(message[end]))) ++end;
      if (end < message.size() && message[end] == '/') ++end;
      message.erase(at, end - at);
    }
    for (std::size_t at; (at = message.find(root)) != std::string::npos;)
      message.erase(at, root.size());
    return message;
  }

  // A fresh folder for one request's copy of its body: work/plans/<n>/.
  fs::path request_folder() {
    const fs::path dir = work / "plans" / std::to_string(++next_id);
    fs::create_directories(dir);
    return dir;
  }

  std::string plan_new(const std::string& body) {
    const std::string source = "plan new request";
    json j = parse_object(body, source);
    refuse_server_keys(j, {"model", "output"}, source);
    // No file named in a request is opened: a procedure is a template of the library here.
    if (j.contains("procedure") && j["procedure"].is_string()) {
      const std::string procedure = j["procedure"];
      if (procedure.find('/') != std::string::npos || fs::path(procedure).extension() == ".json")
        throw InvalidInput(cat(source, ": \"procedure\" ", procedure,
                               ": give a template name "
                               "(GET /api/templates); the server opens no procedure files"));
    }
    j["model"] = current()->dir;
    j["output"] = (request_folder() / "plan.json").string();
    j["force"] = true;
    // The page makes its local charts itself (POST /api/chart, offered under the refusal) and
    // serves them as the model: a plan placed on a chart of its own would not be drawn where it is.
    j["no_chart"] = true;
    return in_page_words(app::find_verb("plan new").run_json(j.dump(), source, nullptr));
  }

  // `name`: what the user calls the plan (the page sends its file's name), for the messages.
  std::string plan_check(const std::string& body, const std::string& name) {
    parse_object(body, "plan check request");
    const fs::path plan = request_folder() / name;
    write_text_atomic(plan, body);
    const json request{{"plan", plan.string()}, {"model", current()->dir}};
    return in_page_words(
        app::find_verb("plan check").run_json(request.dump(), "plan check request", nullptr));
  }

  std::string simulate(const std::string& body) {
    const std::string source = "simulate request";
    // The last request's first answer leaves the board as soon as a new request arrives (the
    // page polls it while its request waits for the running one to stop).
    progress->set_first_answer(nullptr);
    const json j = parse_object(body, source);
    for (const auto& [key, value] : j.items())
      if (key != "plan" && key != "options" && key != "first_answer")
        throw InvalidInput(cat(source, ": unknown key \"", key,
                               "\" (give \"plan\", \"options\" and \"first_answer\")"));
    if (j.contains("first_answer") && !j["first_answer"].is_boolean())
      throw InvalidInput(cat(source, ": \"first_answer\" must be true or false"));
    const bool first_answer = j.value("first_answer", false);
    if (!j.contains("plan") || !j["plan"].is_object())
      throw InvalidInput(cat(source, ": \"plan\" must be a plan file's JSON object"));
    json options_json = j.contains("options") ? j["options"] : json::object();
    if (!options_json.is_object())
      throw InvalidInput(cat(source, ": \"options\" must be an object of simulate options"));
    refuse_server_keys(options_json, {"model", "plan", "output", "force"}, source);
    // Written indented, a body nested 100 deep holding many small values grows a hundredfold:
    // refused before anything is written.
    const std::string plan_text = j["plan"].dump(2) + "\n";
    if (plan_text.size() > 2 * options.max_body_bytes)
      throw InvalidInput(cat(source, ": the plan takes ", plan_text.size(),
                             " bytes written out; a plan file is a few kB"));
    const fs::path plan = request_folder() / "plan.json";
    const int id = ++next_id;
    const std::shared_ptr<const Served> on = current();
    {
      std::lock_guard<std::mutex> lock(served_mutex);
      result_models[id] = on;
    }
    options_json["model"] = on->dir;
    options_json["plan"] = plan.string();
    options_json["output"] = (work / "results" / std::to_string(id)).string();
    const app::VerbEntry& verb = app::find_verb("simulate");
    const std::string request = options_json.dump();
    verb.check_json(request, source);  // a mistake is answered at once, not after the queue
    write_text_atomic(plan, plan_text);
    const std::shared_ptr<SimulationReporter> ticket = new_ticket();
    return run_cancellable(ticket, [=, this, &verb] {
      return simulate_in_slot(*ticket, verb, request, source, options_json, first_answer, on,
                              plan_text, id);
    });
  }

  // simulate()'s work, on its own thread (run_cancellable).
  std::string simulate_in_slot(SimulationReporter& cancellable, const app::VerbEntry& verb,
                               const std::string& request, const std::string& source,
                               const json& options_json, bool first_answer,
                               const std::shared_ptr<const Served>& on,
                               const std::string& plan_text, int id) {
    SimulationSlot slot(*this, cancellable);
    const auto t0 = std::chrono::steady_clock::now();
    const auto since_t0 = [&] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    // The first answer (docs/planner.md, "First answer and time limit"): asked for a
    // finite-strain closure, the same plan is closed first by the linear model on the clamped
    // patch (one small solve), its result kept as a result of its own and put on the progress
    // board, which the page shows while the finite-strain closure runs, and keeps if that one
    // fails or runs out of its time limit.
    std::optional<int> first_id;
    double first_s = 0;
    if (first_answer && options_json.value("material", std::string()) != "linear")
      first_id = simulate_first_answer(options_json, on, plan_text, source, cancellable, t0);
    if (first_id) first_s = since_t0();
    const std::string result = verb.run_json(request, source, &cancellable);
    const double total_s = since_t0();
    progress->finish();
    // The plan beside its result, for exporting them together.
    write_text_atomic(work / "results" / std::to_string(id) / "plan.json", plan_text);
    json out = json::parse(result);
    // Where the time went (not reproducible, so under timings_s): each progress step, and the
    // whole request's simulation, files included.
    out["timings_s"]["steps"] = progress->steps_s();
    out["timings_s"]["simulate"] = total_s;
    out["result_id"] = id;
    out["result_url"] = cat("/api/results/", id, "/");
    if (first_id) {
      out["first_answer_id"] = *first_id;
      out["timings_s"]["first_answer"] = first_s;
    }
    detail::page_words_json(out, *on->model, on->dir);
    return out.dump(2);
  }

  // POST /api/suggest: caps plan suggest for a lesion on the served model ({"at" | "at_xyz",
  // "diameter", and the verb's other options}), in the simulation's slot: a newer simulate or
  // suggest request, DELETE /api/simulate and the server's stop cancel it (409), and
  // /api/progress shows its progress. Answers suggestions.json with result_id and result_url:
  // the polar plot is result_url + "suggestions.png", each design's plan result_url + its "plan".
  std::string suggest(const std::string& body) {
    const std::string source = "suggest request";
    progress->set_first_answer(nullptr);
    json j = parse_object(body, source);
    refuse_server_keys(j, {"model", "output", "force"}, source);
    const int id = ++next_id;
    const std::shared_ptr<const Served> on = current();
    {
      std::lock_guard<std::mutex> lock(served_mutex);
      result_models[id] = on;
    }
    j["model"] = on->dir;
    j["output"] = (work / "results" / std::to_string(id)).string();
    const app::VerbEntry& verb = app::find_verb("plan suggest");
    const std::string request = j.dump();
    verb.check_json(request, source);  // a mistake is answered at once, not after the queue
    const std::shared_ptr<SimulationReporter> ticket = new_ticket();
    return run_cancellable(ticket, [=, this, &verb] {
      return suggest_in_slot(*ticket, verb, request, source, on, id);
    });
  }

  // suggest()'s work, on its own thread (run_cancellable).
  std::string suggest_in_slot(SimulationReporter& cancellable, const app::VerbEntry& verb,
                              const std::string& request, const std::string& source,
                              const std::shared_ptr<const Served>& on, int id) {
    SimulationSlot slot(*this, cancellable);
    const auto t0 = std::chrono::steady_clock::now();
    verb.run_json(request, source, &cancellable);
    json out = json::parse(read_file(work / "results" / std::to_string(id) / "suggestions.json"));
    out["timings_s"]["suggest"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out["result_id"] = id;
    out["result_url"] = cat("/api/results/", id, "/");
    out.erase("output");
    detail::page_words_json(out, *on->model, on->dir);
    return out.dump(2);
  }

  // The linear closure of the simulate request `options_json` (a finite-strain one) on the
  // clamped patch, as a result of its own, put on the progress board; its id. A request the
  // linear model refuses (an option of the finite-strain model alone) has no first answer: the
  // finite-strain closure answers.
  std::optional<int> simulate_first_answer(json options_json, const std::shared_ptr<const Served>& on,
                                           const std::string& plan_text, const std::string& source,
                                           Reporter& cancellable,
                                           std::chrono::steady_clock::time_point t0) {
    const int id = ++next_id;
    {
      std::lock_guard<std::mutex> lock(served_mutex);
      result_models[id] = on;
    }
    const fs::path out_dir = work / "results" / std::to_string(id);
    // Linear, on the 1992 patch clamped at its rim: one solve of a few ten thousand unknowns
    // (0.35 s for the page's default Z-plasty on Cranium's forehead, against 2.8 s in the whole
    // face: docs/planner.md). A preview, labelled so; the finite-strain closure is in the face.
    options_json["material"] = "linear";
    options_json["domain"] = "patch";
    options_json["no_mesh_pictures"] = true;  // not shown by the page; a tenth of its time
    options_json.erase("face_radius");
    options_json.erase("time_limit");
    options_json["output"] = out_dir.string();
    json first;
    try {
      first = json::parse(
          app::find_verb("simulate").run_json(options_json.dump(), source, &cancellable));
    } catch (const Cancelled&) {
      throw;
    } catch (const Error& e) {
      caps::note(reporter, cat("no first answer: the linear closure failed (", e.what(), ")"));
      return std::nullopt;
    }
    write_text_atomic(out_dir / "plan.json", plan_text);
    first["timings_s"]["simulate"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    first["result_id"] = id;
    first["result_url"] = cat("/api/results/", id, "/");
    detail::page_words_json(first, *on->model, on->dir);
    progress->set_first_answer(first);
    return id;
  }

  // The plan in the body, read as `caps plan check` reads a plan file (from the work folder).
  plan::Plan plan_of(const std::string& body, const std::string& source) {
    parse_object(body, source);
    const fs::path file = request_folder() / "plan.json";
    write_text_atomic(file, body);
    return plan::read_plan(file);
  }

  // The model's skin as a .glb (written once into the work folder) and its JSON description.
  json model_skin(detail::SkinColouring colouring) {
    const std::string name = colouring == detail::SkinColouring::Skin ? "skin" : "thickness";
    const std::shared_ptr<const Served> on = current();
    const fs::path folder = skin_folder(*on);
    const fs::path glb = folder / (name + ".glb"), info = folder / (name + ".json");
    std::lock_guard<std::mutex> lock(views_mutex);
    if (!fs::is_regular_file(info)) {
      fs::create_directories(folder);
      // The drawn skin's range (slice terraces filtered, resampled from the skin isosurface):
      // what caps render draws, on the model's grid, so the page's vertices are the samples.
      write_text_atomic(info, detail::write_model_skin_glb(app::loaded_drawn_skin(on->dir)->range,
                                                           colouring, glb));
    }
    json j = json::parse(read_file(info));
    j["url"] = cat("/api/skin/", name, ".glb");
    return j;
  }

  fs::path skin_folder(const Served& on) const {
    return work / "skin" / std::to_string(on.generation);
  }

  // The model a result was simulated on (the current one for a result the server did not make).
  std::shared_ptr<const Served> model_of(const std::string& id) {
    std::lock_guard<std::mutex> lock(served_mutex);
    const auto it = result_models.find(std::atoi(id.c_str()));
    return it != result_models.end() ? it->second : served;
  }

  // POST /api/chart {"at": "THETA,Z"} or {"at_xyz": "X,Y,Z"} on the started model: makes a local
  // chart of it there (caps model chart) and serves the chart from then on; {"head": true} goes
  // back to the started model. Answers the served model's model.json.
  std::string chart(const std::string& body) {
    const std::string source = "chart request";
    const json j = parse_object(body, source);
    for (const auto& [key, value] : j.items())
      if (key != "at" && key != "at_xyz" && key != "head")
        throw InvalidInput(cat(source, ": unknown key \"", key, "\" (give \"at\", \"at_xyz\" "
                               "or \"head\")"));
    if (j.contains("head") && j["head"] == true) {
      std::lock_guard<std::mutex> lock(served_mutex);
      served = head;
      return read_file(fs::path(head->dir) / "model.json");
    }
    const int n = ++next_id;
    json request = j;
    request.erase("head");
    request["model"] = head->dir;
    request["output"] = (work / "charts" / std::to_string(n)).string();
    const app::VerbEntry& verb = app::find_verb("model chart");
    verb.check_json(request.dump(), source);
    fs::create_directories(work / "charts");
    verb.run_json(request.dump(), source, reporter);
    auto next = std::make_shared<Served>();
    next->dir = fs::absolute(request["output"].get<std::string>()).lexically_normal().string();
    next->model = app::loaded_model(next->dir);
    next->generation = n;
    {
      std::lock_guard<std::mutex> lock(served_mutex);
      served = next;
    }
    return read_file(fs::path(next->dir) / "model.json");
  }

  // A simulation's skin before and after as .glb files (written once) and their description.
  json result_view(const std::string& id) {
    const fs::path dir = work / "results" / id;
    if (!fs::is_regular_file(dir / "result.json"))
      throw Refusal(404, cat("simulation ", id, ": no such result"));
    const fs::path info = dir / "view.json";
    std::lock_guard<std::mutex> lock(views_mutex);
    if (!fs::is_regular_file(info)) {
      const std::shared_ptr<const Served> on = model_of(id);
      detail::ResultView view =
          detail::write_result_skin_glbs(*on->model, app::loaded_drawn_skin(on->dir).get(), dir);
      write_text_atomic(info, view.json);
      // tension.glb after the answer: the page draws the skin first (GET .../tension.glb waits).
      tension_files[id] = std::async(std::launch::async, std::move(view.write_tension)).share();
    }
    json j = json::parse(read_file(info));
    for (const char* k : {"skin", "tension", "tension_values", "moved_skin", "moved_skin_tension"})
      if (j.value(k, json()).is_string()) j[k] = cat("/api/results/", id, "/", j[k].get<std::string>());
    return j;
  }

  // A simulation's pictures and 3D skin as `caps render RESULT --gltf --tension-map --plan PLAN`
  // writes them (into the result's export/ folder, once), for downloading from the page.
  json result_export(const std::string& id) {
    const fs::path dir = work / "results" / id;
    if (!fs::is_regular_file(dir / "result.json"))
      throw Refusal(404, cat("simulation ", id, ": no such result"));
    const fs::path info = dir / "export.json";
    std::lock_guard<std::mutex> lock(export_mutex);
    if (!fs::is_regular_file(info)) {
      const json r{{"result", dir.string()},
                   {"model", model_of(id)->dir},
                   {"output", (dir / "export").string()},
                   {"plan", (dir / "plan.json").string()},
                   {"gltf", true},
                   {"tension_map", true},
                   {"force", true}};
      write_text_atomic(info, app::find_verb("render").run_json(r.dump(), "export request",
                                                                reporter));
    }
    json rendered = json::parse(read_file(info));
    json files = json::array();
    const std::string base = cat("/api/results/", id, "/");
    for (const char* f : {"plan.json", "result.json", "summary.json"})
      if (fs::is_regular_file(dir / f)) files.push_back({{"name", f}, {"url", base + f}});
    if (fs::is_regular_file(dir / "export" / "skin.glb"))
      files.push_back({{"name", "skin.glb"}, {"url", base + "export/skin.glb"}});
    for (const auto& image : rendered.value("images", json::array()))
      files.push_back({{"name", image}, {"url", base + "export/" + image.get<std::string>()}});
    return json{{"files", files}, {"render", rendered}};
  }

  // A result's tension.glb, tension_kpa.f32 or tension_moved_skin_kpa.bin (`name`), once
  // result_view() has started writing them.
  fs::path tension_file(const std::string& id, const std::string& name) {
    std::shared_future<void> job;
    {
      std::lock_guard<std::mutex> lock(views_mutex);
      const auto it = tension_files.find(id);
      if (it != tension_files.end()) job = it->second;
    }
    if (job.valid()) job.get();  // rethrows the writer's error
    return file_under(work / "results" / id, name);
  }

  void add_routes() {
    http.set_payload_max_length(options.max_body_bytes);
    // Errors httplib answers itself (413 for a body over the limit, 404 for no route, 400 for a
    // malformed request line) get the same {"error": ...} body as the routes' own.
    http.set_error_handler(httplib::Server::HandlerWithResponse(
        [this](const httplib::Request& req, httplib::Response& res) {
          if (!res.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
          // A chunked body over the limit ends its reading as a malformed one would.
          const detail::ConnectionState* connection = detail::GuardedHttpServer::current();
          if (connection && connection->body_too_large) res.status = 413;
          if (res.status == 413) res.set_header("Connection", "close");
          std::string message;
          if (res.status == 413)
            message = cat("the request body is larger than ", options.max_body_bytes,
                          " bytes (the server's limit); send one plan at a time");
          else if (res.status == 404)
            message = cat(req.method, " ", req.path, ": no such route (see docs/planner.md)");
          else
            message = cat("bad request (HTTP ", res.status, ")");
          send_error(res, res.status, message);
          return httplib::Server::HandlerResponse::Handled;
        }));
    // Every request is screened (Host, Origin, token, path) once its headers are in, before
    // its body is read; a refused one closes its connection (its body is never read).
    http.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      const std::optional<ErrorResponse> refusal = screen(req);
      if (!refusal) return httplib::Server::HandlerResponse::Unhandled;
      ++n_requests;
      send_error(res, refusal->status, refusal->message);
      res.set_header("Connection", "close");
      if (detail::ConnectionState* connection = detail::GuardedHttpServer::current())
        connection->close = true;
      return httplib::Server::HandlerResponse::Handled;
    });

    // model.json of the served model; a chart made through POST /api/chart also says so
    // ("made_here": the page offers the way back to the started model).
    http.Get("/api/model", guarded([this](const httplib::Request&, httplib::Response& res) {
               const std::shared_ptr<const Served> on = current();
               if (on == head) return send_file(res, file_under(on->dir, "model.json"));
               json j = json::parse(read_file(file_under(on->dir, "model.json")));
               j["made_here"] = true;
               send_json(res, j.dump(2));
             }));
    http.Post("/api/chart", guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, chart(req.body));
              }));
    // The model's anatomical landmarks (docs/landmarks.md), found without writing model.json.
    http.Get("/api/landmarks",
             guarded([this](const httplib::Request&, httplib::Response& res) {
               const json r{{"model", current()->dir}, {"no_write", true}};
               send_json(res, app::find_verb("model landmarks")
                                  .run_json(r.dump(), "landmarks request", nullptr));
             }));
    // The relaxed skin tension lines over the face (`caps plan skin-lines MODEL --json`).
    http.Get("/api/skin-lines",
             guarded([this](const httplib::Request&, httplib::Response& res) {
               const json r{{"model", current()->dir}};
               send_json(res, app::find_verb("plan skin-lines")
                                  .run_json(r.dump(), "skin lines request", nullptr));
             }));
    http.Get(R"(/api/model/(.+))",
             guarded([this](const httplib::Request& req, httplib::Response& res) {
               send_file(res, file_under(current()->dir, req.matches[1]));
             }));
    http.Get("/api/skin", guarded([this](const httplib::Request&, httplib::Response& res) {
               send_json(res, json{{"skin", model_skin(detail::SkinColouring::Skin)},
                                   {"thickness", model_skin(detail::SkinColouring::Thickness)}}
                                  .dump());
             }));
    http.Get(R"(/api/skin/(skin|thickness)\.glb)",
             guarded([this](const httplib::Request& req, httplib::Response& res) {
               const bool skin = req.matches[1] == "skin";
               model_skin(skin ? detail::SkinColouring::Skin : detail::SkinColouring::Thickness);
               send_file(res, skin_folder(*current()) / (skin ? "skin.glb" : "thickness.glb"));
             }));
    http.Get("/api/progress", guarded([this](const httplib::Request&, httplib::Response& res) {
               send_json(res, progress->snapshot().dump());
             }));
    http.Post("/api/plan/lines",
              guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, detail::plan_lines_json(plan_of(req.body, "plan lines request"),
                                                       *current()->model));
              }));
    http.Get(R"(/api/results/([0-9]+)/view)",
             guarded([this](const httplib::Request& req, httplib::Response& res) {
               send_json(res, result_view(req.matches[1]).dump());
             }));
    http.Get(R"(/api/results/([0-9]+)/(tension\.glb|tension_kpa\.f32|tension_moved_skin_kpa\.bin))",
             guarded([this](const httplib::Request& req, httplib::Response& res) {
               send_file(res, tension_file(req.matches[1], req.matches[2]));
             }));
    http.Post(R"(/api/results/([0-9]+)/export)",
              guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, result_export(req.matches[1]).dump());
              }));
    http.Get("/api/templates", guarded([](const httplib::Request&, httplib::Response& res) {
               send_json(res, app::find_verb("plan templates").run_json("{}", "templates", nullptr));
             }));
    http.Post("/api/plan/new", guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, plan_new(req.body));
              }));
    http.Post("/api/plan/check",
              guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, plan_check(req.body, plan_name(req)));
              }));
    http.Post("/api/simulate", guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, simulate(req.body));
              }));
    http.Post("/api/suggest", guarded([this](const httplib::Request& req, httplib::Response& res) {
                send_json(res, suggest(req.body));
              }));
    // Cancels the running simulation (the page's Cancel button, a page left): it ends within a
    // second and its request is answered 409.
    http.Delete("/api/simulate",
                guarded([this](const httplib::Request&, httplib::Response& res) {
                  const bool running = progress->snapshot().value("running", false);
                  ++latest_simulation;
                  progress->cancel();
                  send_json(res, json{{"cancelled", running}}.dump());
                }));
    http.Get(R"(/api/results/([0-9]+)/(.+))",
             guarded([this](const httplib::Request& req, httplib::Response& res) {
               send_file(
                   res, file_under(work / "results" / std::string(req.matches[1]), req.matches[2]));
             }));
    http.Get(R"(/api/.*)", guarded([](const httplib::Request& req, httplib::Response&) {
               throw Refusal(404, cat("GET ", req.path, ": no such route (see docs/planner.md)"));
             }));
    http.Get(R"(/.*)", guarded([this](const httplib::Request& req, httplib::Response& res) {
               std::string path = req.path.substr(1);
               if (path.empty() || path.back() == '/') path += "index.html";
               if (placeholder && path != "index.html")
                 throw Refusal(404,
                               cat("\"", req.path, "\": no such file (the page is not built yet)"));
               const fs::path file = file_under(web, path);
               if (file.extension() != ".html") return send_file(res, file);
               // The page's session token: in a meta element its requests read, and in a cookie
               // (same site only) that links and loaders send; never cached.
               std::string html = read_file(file);
               const std::string meta = cat("<meta name=\"caps-token\" content=\"", token, "\">");
               const std::size_t head = html.find("<head>");
               html.insert(head == std::string::npos ? 0 : head + 6, meta);
               res.set_header("Cache-Control", "no-store");
               res.set_header("Set-Cookie", cat(token_cookie(), "=", token,
                                                "; Path=/; SameSite=Strict; HttpOnly"));
               res.set_content(html, content_type(file).c_str());
             }));
  }
};

PlannerServer::PlannerServer(ServerOptions options, Reporter* reporter)
    : impl_(std::make_unique<Impl>(std::move(options), reporter)) {
  Impl& s = *impl_;
  if (s.options.host.empty()) throw InvalidInput("--host: give an address to bind, e.g. 127.0.0.1");
  for (const std::string& name : s.options.allowed_hosts)
    if (name.empty() || name.size() > 253 ||
        name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-") !=
            std::string::npos)
      throw InvalidInput(cat("--allow-host '", name, "': give host names or IPv4 addresses "
                             "(letters, digits, '.' and '-'), separated by commas"));
  if (s.options.port < 0 || s.options.port > 65535)
    throw InvalidInput(cat("--port ", s.options.port, ": give 1..65535 (0: any free port)"));
  // Loaded once and kept (the CLI's message for a missing or broken model); every request on
  // this model reuses it while its files are unchanged.
  auto head = std::make_shared<Impl::Served>();
  head->model = app::loaded_model(s.options.model_dir);
  s.progress = std::make_unique<ProgressBoard>(s.reporter);
  // Plans name their model: absolute, so that a plan saved from the page works from any folder.
  s.options.model_dir = fs::absolute(s.options.model_dir).lexically_normal().string();
  head->dir = s.options.model_dir;
  s.head = s.served = head;
  if (s.options.web_root.empty()) {
    s.web = default_web_root();
    s.placeholder = s.web == fs::path(CAPS_WEB_DIR);
  } else {
    s.web = s.options.web_root;
    if (!fs::is_directory(s.web))
      throw IoError(cat("--web-root ", s.options.web_root, ": no such folder"));
  }
  s.set_allowed_hosts(s.options.port);
  remove_stale_work_dirs();
  s.work = make_work_dir();
  try {
    s.add_routes();
  } catch (...) {
    std::error_code ec;
    fs::remove_all(s.work, ec);
    throw;
  }
}

PlannerServer::~PlannerServer() {
  stop();
  impl_->wait_for_workers();  // cancelled by stop(); each ends at its next check
  for (auto& [id, job] : impl_->tension_files) job.wait();
  std::error_code ec;
  fs::remove_all(impl_->work, ec);
}

int PlannerServer::bind() {
  Impl& s = *impl_;
  if (!is_loopback(s.options.host))
    warn(s.reporter, cat("listening on ", s.options.host,
                         ", not only on this machine (127.0.0.1): "
                         "anyone who can reach it can use the planner and read the model",
                         s.options.allowed_hosts.empty()
                             ? std::string("; it answers requests addressed to this machine's "
                                           "loopback names only: give the name other machines "
                                           "use with --allow-host")
                             : std::string()));
  s.port = s.options.port == 0
               ? s.http.bind_to_any_port(s.options.host)
               : (s.http.bind_to_port(s.options.host, s.options.port) ? s.options.port : -1);
  if (s.port <= 0) {
    s.port = 0;
    throw IoError(cat("cannot listen on ", s.options.host, ":", s.options.port,
                      "; is another server using the port? try --port 0 or another one"));
  }
  s.http.widen_backlog();
  s.set_allowed_hosts(s.port);
  return s.port;
}

void PlannerServer::listen() {
  Impl& s = *impl_;
  if (s.port == 0) bind();
  s.listening = true;
  if (!s.stop_requested) s.http.listen_after_bind();
  s.listening = false;
}

void PlannerServer::stop() {
  Impl& s = *impl_;
  s.stop_requested = true;  // also cancels a running simulation (SimulationReporter)
  // listen() may not have started its loop yet; httplib's stop() does nothing before it has.
  for (int i = 0; i < 200 && s.listening && !s.http.is_running(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  s.http.stop();
}

int PlannerServer::port() const { return impl_->port; }

std::string PlannerServer::url() const {
  const std::string& h = impl_->options.host;
  const bool v6 = h.find(':') != std::string::npos;
  return cat("http://", v6 ? "[" + h + "]" : h, ":", impl_->port, "/");
}

const fs::path& PlannerServer::work_dir() const { return impl_->work; }
const fs::path& PlannerServer::web_root() const { return impl_->web; }
long PlannerServer::n_requests() const { return impl_->n_requests.load(); }
const std::string& PlannerServer::token() const { return impl_->token; }
const std::vector<std::string>& PlannerServer::allowed_hosts() const {
  return impl_->allowed_hosts;
}

std::string PlannerServer::answer(const std::string& request) {
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM, 0, fds) != 0)
    throw IoError(cat("cannot make a socket pair: ", std::strerror(errno)));
  std::thread server([&] { impl_->http.serve_socket(fds[1]); });  // closes fds[1]
  std::thread writer([&] {
    for (std::size_t sent = 0; sent < request.size();) {
      const ssize_t n = ::send(fds[0], request.data() + sent, request.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) break;
      sent += static_cast<std::size_t>(n);
    }
    ::shutdown(fds[0], SHUT_WR);
  });
  std::string out;
  char buffer[16384];
  for (ssize_t n; (n = ::recv(fds[0], buffer, sizeof(buffer), 0)) > 0;) out.append(buffer, n);
  writer.join();
  server.join();
  ::close(fds[0]);
  return out;
}

}  // namespace caps::server
