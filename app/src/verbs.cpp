#include "caps/app/verbs.hpp"

#include "caps/app/run_guard.hpp"

#include "caps/core/error.hpp"

namespace caps::app {

std::string verb_key(std::string_view name) {
  std::string key(name);
  for (char& c : key)
    if (c == ' ' || c == '-') c = '_';
  return key;
}

const std::vector<VerbEntry>& verbs() {
  static const std::vector<VerbEntry> list = [] {
    std::vector<VerbEntry> v;
    for_each_verb([&v](const auto& verb) {
      using Request = typename std::decay_t<decltype(verb)>::request_type;
      const auto run = verb.run;
      v.push_back({std::string(verb.name), verb_key(verb.name), std::string(verb.help),
                   verb.answer,
                   [run](const std::string& json, const std::string& source, Reporter* reporter) {
                     const Request request = read_request<Request>(json, source);
                     const auto claim = claim_output(request);  // held for the run
                     return to_json(run(request, reporter));
                   },
                   [](const std::string& json, const std::string& source) {
                     read_request<Request>(json, source);
                   },
                   [] { return write_request(Request{}); }});
    });
    return v;
  }();
  return list;
}

const VerbEntry& find_verb(std::string_view name) {
  const std::string key = verb_key(name);
  for (const VerbEntry& v : verbs())
    if (v.key == key) return v;
  std::string known;
  for (const VerbEntry& v : verbs()) known += (known.empty() ? "" : ", ") + v.key;
  throw InvalidInput(cat("no verb \"", name, "\"; the verbs are ", known));
}

}  // namespace caps::app
