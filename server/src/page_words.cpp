#include "page_words.hpp"

#include <cmath>
#include <optional>
#include <regex>

#include "caps/core/error.hpp"
#include "caps/plan/placement.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::server::detail {

namespace {

// Replaces every match of `re` in `text` by what `f` makes of it.
template <class F>
std::string replace_each(const std::string& text, const std::regex& re, F f) {
  std::string out;
  auto last = text.cbegin();
  for (std::sregex_iterator it(text.begin(), text.end(), re), end; it != end; ++it) {
    out.append(last, (*it)[0].first);
    out += f(*it);
    last = (*it)[0].second;
  }
  out.append(last, text.cend());
  return out;
}

// "12 mm to the patient's left and 3 mm up from the glabella" for (theta, z), or nullopt.
std::optional<std::string> near_words(const PatientModel& model, const std::string& model_dir,
                                      double theta_deg, double z_mm) {
  try {
    const auto near = plan::nearest_kept_landmark_placement(model_dir, model, theta_deg, z_mm);
    if (!near) return std::nullopt;
    return plan::placement_in_words(*near);
  } catch (const std::exception&) {
    return std::nullopt;  // a message is still shown, without the place
  }
}

// The command line's options of `caps simulate` and `caps plan new` the page has as settings.
struct PageSetting {
  const char* option;
  const char* words;
};
constexpr PageSetting kPageSettings[] = {
    {"mesh-size", "the Mesh size setting"},
    {"material", "the Material setting"},
    {"time-limit", "the Time limit setting"},
    {"extent", "a smaller procedure (its length and width)"},
    {"at", "a click on the skin"},
    {"tissue uniform", "the Tissue setting's one material"},
    {"tissue auto", "the Tissue setting's measured layers"},
    {"tissue measured", "the Tissue setting's measured layers"},
    {"tissue", "the Tissue setting"},
};

constexpr std::size_t kMaxReworded = 2000;

}  // namespace

std::string page_words(const std::string& message, const PatientModel& model,
                       const std::string& model_dir) {
  static const std::regex chart_advice(
      R"(,? ?(or )?make a local chart that faces this skin \(caps model chart [^)]*\) and plan on it at --at 0,0 \(docs/mesher\.md, "Local charts"\))");
  static const std::regex chart_here(R"( ?\(here: caps model chart [^)]*\))");
  static const std::regex chart_any(R"(caps model chart [^;,.)]*)");
  static const std::regex node_point(R"(loop node \d+ \(point (\d+)\)(, /points/\d+)?)");
  static const std::regex node_alone(R"(loop node \d+)");
  static const std::regex edge(R"(loop edge \(\d+,\d+\))");
  static const std::regex border_edges(R"(border edges not sutured \(the wound stays open there\): [()0-9, ]+)");
  static const std::regex suture(R"(suture (\d+) (\(/sutures/\d+\) )?[()0-9,]*:)");
  static const std::regex edge_alone(R"((border )?edge \(\d+,\d+\))");
  static const std::regex pointer(R"( ?\(?/(points|sutures|frame)/[A-Za-z0-9_/]*\)?)");
  static const std::regex theta_z(
      R"(\(?theta (-?[0-9.eE+-]+) deg,? z (-?[0-9.eE+-]+) mm\)?)");
  static const std::regex option(R"(`?--([a-z][a-z-]*)( [A-Za-z0-9.,=+-]+)?`?)");
  // std::regex matches recursively: a message that echoes a long piece of a request is left as
  // it is rather than risk the stack (the library's own messages are a few hundred characters).
  if (message.size() > kMaxReworded) return message;
  std::string s = message;
  s = std::regex_replace(s, chart_advice, ", or make a local chart here (the button below)");
  // Said once: the advice above names the button already.
  s = std::regex_replace(s, chart_here, "");
  s = std::regex_replace(s, chart_any, "a local chart (the button below)");
  const auto plus_one = [](const std::string& digits) {
    try {
      return std::to_string(std::stoll(digits) + 1);
    } catch (const std::exception&) {
      return digits;  // too many digits for a number: said as it was
    }
  };
  s = replace_each(s, node_point, [&](const std::smatch& m) {
    return cat("the cut's point ", plus_one(m[1].str()));
  });
  s = std::regex_replace(s, node_alone, "a corner of the wound");
  s = std::regex_replace(s, edge, "a stretch of the wound's edge");
  s = std::regex_replace(s, border_edges, "some of the wound's edges are not sutured (the wound stays open there)");
  s = replace_each(s, suture, [&](const std::smatch& m) {
    return cat("suture pair ", plus_one(m[1].str()), ":");
  });
  s = std::regex_replace(s, edge_alone, "an edge of the wound");
  s = std::regex_replace(s, pointer, "");
  s = replace_each(s, theta_z, [&](const std::smatch& m) -> std::string {
    double theta = 0, z = 0;
    try {
      theta = std::stod(m[1].str());
      z = std::stod(m[2].str());
    } catch (const std::exception&) {
      return "(there)";  // not numbers after all ("theta - deg"): the place is not said
    }
    const auto words = near_words(model, model_dir, theta, z);
    return words ? cat("(", *words, ")") : std::string("(there)");
  });
  s = replace_each(s, option, [](const std::smatch& m) -> std::string {
    const std::string with_value = m[2].matched ? m[1].str() + m[2].str() : std::string();
    for (const PageSetting& p : kPageSettings)
      if (with_value == p.option) return p.words;
    for (const PageSetting& p : kPageSettings)
      if (m[1].str() == p.option) return std::string(p.words);
    return cat("a setting of the command line (", m[1].str(), ")");
  });
  return s;
}

void page_words_json(nlohmann::json& answer, const PatientModel& model,
                     const std::string& model_dir) {
  if (answer.is_object()) {
    for (auto& [key, value] : answer.items()) {
      if (key == "warnings" && value.is_array()) {
        for (auto& w : value)
          if (w.is_string()) w = page_words(w.get<std::string>(), model, model_dir);
      } else if (value.is_object() || value.is_array()) {
        page_words_json(value, model, model_dir);
      }
    }
  } else if (answer.is_array()) {
    for (auto& v : answer) page_words_json(v, model, model_dir);
  }
}

}  // namespace caps::server::detail
