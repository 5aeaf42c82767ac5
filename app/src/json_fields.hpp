#pragma once
// The JSON side of the declared fields of requests and results (app/include/caps/app/fields.hpp),
// for app/src only.

#include <nlohmann/json.hpp>
#include <Eigen/Core>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"

namespace caps::app::detail {

using nlohmann::json;

/// How every JSON text of app/ is written: indented by 2, UTF-8, invalid bytes replaced.
inline std::string dump(const json& j) {
  return j.dump(2, ' ', false, json::error_handler_t::replace);
}

/// Fills a request's or a result's fields from a JSON object.
class JsonReader {
 public:
  JsonReader(const json& j, std::string source) : source_(std::move(source)) {
    levels_.push_back({&j, "", {}});
  }

  template <class T>
  void operator()(T& value, const Field& f) {
    const json* v = take(f);
    if (v && !v->is_null()) read(*v, value, name(f.key));
  }

  /// A nested object of fields: "lengthening": {...}.
  template <class F>
  void group(const Field& f, F&& fields) {
    const json* v = take(f);
    if (!v) return;
    if (!v->is_object()) wrong(name(f.key), "an object", *v);
    levels_.push_back({v, name(f.key) + ".", {}});
    fields();
    check_unknown_here();
    levels_.pop_back();
  }

  /// Fields written only when `condition` holds; read when present, and a bool flag given as
  /// the condition is set to whether they were.
  template <class B, class F>
  void when(B&& condition, F&& fields) {
    const std::size_t before = found_;
    ++optional_;
    fields();
    --optional_;
    if constexpr (std::is_same_v<B, bool&>) condition = found_ > before;
  }

  /// A value computed from other fields: written, not read back.
  template <class F>
  void computed(const Field& f, F&&) {
    take(f);
  }

  /// The pair [a, b] under one key.
  template <class T>
  void pair(T& a, T& b, const Field& f) {
    const json* v = take(f);
    if (!v) return;
    if (!v->is_array() || v->size() != 2) wrong(name(f.key), "a pair [a, b]", *v);
    read((*v)[0], a, name(f.key) + "[0]");
    read((*v)[1], b, name(f.key) + "[1]");
  }

  /// A JSON value under one key, kept as its text.
  void json_value(std::string& text, const Field& f) {
    if (const json* v = take(f)) text = dump(*v);
  }

  /// A JSON document whose keys sit beside the declared ones: it takes every key that is no
  /// field (or, alone, the whole value).
  void document(std::string& text, const Field&) { document_ = &text; }

  /// Refuses keys that are no field (or hands them to the document).
  void finish() {
    const Level& top = levels_.front();
    if (document_) {
      if (!top.j->is_object()) {
        *document_ = dump(*top.j);
        return;
      }
      json rest = json::object();
      for (const auto& [k, v] : top.j->items())
        if (!top.seen.count(k)) rest[k] = v;
      *document_ = dump(rest);
      return;
    }
    check_unknown_here();
  }

 private:
  struct Level {
    const json* j;
    std::string prefix;  // "lengthening." inside a group
    std::set<std::string> seen;
  };

  std::string name(std::string_view key) const { return levels_.back().prefix + std::string(key); }

  // The value of the field's key at this level (marked as seen), or null when it is absent.
  const json* take(const Field& f) {
    Level& l = levels_.back();
    const std::string key(f.key);
    l.seen.insert(key);
    if (!l.j->is_object() || !l.j->contains(key)) {
      if (!optional_ && (f.kind == FieldKind::Required || f.kind == FieldKind::Positional))
        throw InvalidInput(cat(source_, ": \"", name(key), "\" is required (", f.help, ")"));
      return nullptr;
    }
    ++found_;
    return &l.j->at(key);
  }

  void check_unknown_here() const {
    const Level& l = levels_.back();
    for (const auto& [k, v] : l.j->items())
      if (!l.seen.count(k)) throw InvalidInput(cat(source_, ": unknown key \"", l.prefix, k, "\""));
  }

  [[noreturn]] void wrong(const std::string& key, const char* expected, const json& v) const {
    throw InvalidInput(cat(source_, ": \"", key, "\" must be ", expected, ", not ",
                           v.dump(-1, ' ', false, json::error_handler_t::replace)));
  }
  void read(const json& v, std::string& x, const std::string& k) {
    if (!v.is_string()) wrong(k, "a string", v);
    x = v.get<std::string>();
  }
  void read(const json& v, bool& x, const std::string& k) {
    if (!v.is_boolean()) wrong(k, "true or false", v);
    x = v.get<bool>();
  }
  void read(const json& v, double& x, const std::string& k) {
    if (!v.is_number()) wrong(k, "a number", v);
    x = v.get<double>();
  }
  void read(const json& v, std::optional<double>& x, const std::string& k) {
    double d = 0;
    read(v, d, k);
    x = d;
  }
  void read(const json& v, int& x, const std::string& k) {
    if (!v.is_number_integer()) wrong(k, "a whole number", v);
    const auto i = v.get<long long>();
    if (i < -(1LL << 31) || i > (1LL << 31) - 1) wrong(k, "a whole number in range", v);
    x = static_cast<int>(i);
  }
  void read(const json& v, std::map<std::string, double>& x, const std::string& k) {
    if (!v.is_object()) wrong(k, "an object of numbers", v);
    for (const auto& [name, value] : v.items()) {
      if (!value.is_number()) wrong(k + "." + name, "a number", value);
      x[name] = value.get<double>();
    }
  }
  void read(const json& v, std::vector<std::string>& x, const std::string& k) {
    if (!v.is_array()) wrong(k, "an array of strings", v);
    x.clear();
    for (const auto& s : v) {
      if (!s.is_string()) wrong(k, "an array of strings", v);
      x.push_back(s.get<std::string>());
    }
  }
  template <class S, int N>
  void read(const json& v, Eigen::Matrix<S, N, 1>& x, const std::string& k) {
    if (!v.is_array() || v.size() != std::size_t(N)) wrong(k, "an array of 3 numbers", v);
    for (int i = 0; i < N; ++i) read(v[std::size_t(i)], x[i], cat(k, "[", i, "]"));
  }

  std::string source_;
  std::vector<Level> levels_;
  std::string* document_ = nullptr;
  int optional_ = 0;        // inside when(): required fields may be absent
  std::size_t found_ = 0;   // keys found so far
};

/// Writes a request's or a result's fields into a JSON object.
class JsonWriter {
 public:
  JsonWriter() { stack_.push_back(&j); }

  template <class T>
  void operator()(const T& value, const Field& f) {
    here()[std::string(f.key)] = value_of(value);
  }

  template <class F>
  void group(const Field& f, F&& fields) {
    json& g = here()[std::string(f.key)] = json::object();
    stack_.push_back(&g);
    fields();
    stack_.pop_back();
  }

  template <class B, class F>
  void when(B&& condition, F&& fields) {
    if (condition) fields();
  }

  template <class F>
  void computed(const Field& f, F&& value) {
    here()[std::string(f.key)] = value_of(value());
  }

  template <class T>
  void pair(const T& a, const T& b, const Field& f) {
    here()[std::string(f.key)] = json::array({value_of(a), value_of(b)});
  }

  void json_value(const std::string& text, const Field& f) {
    try {
      here()[std::string(f.key)] = json::parse(text);
    } catch (const json::exception& e) {
      throw Error(cat("the result's \"", f.key, "\" is not JSON (", e.what(), ")"));
    }
  }

  void document(const std::string& text, const Field& f) {
    json d;
    try {
      d = json::parse(text);
    } catch (const json::exception& e) {
      throw Error(cat("the result's \"", f.key, "\" is not JSON (", e.what(), ")"));
    }
    if (d.is_object())
      here().update(d);
    else
      here() = std::move(d);  // a document alone: an array (the templates) is the whole result
  }

  json j = json::object();

 private:
  json& here() { return *stack_.back(); }

  template <class T>
  static json value_of(const T& value) {
    if constexpr (std::is_same_v<T, std::optional<double>>) {
      return value ? json(*value) : json(nullptr);
    } else if constexpr (std::is_base_of_v<Eigen::MatrixBase<T>, T>) {
      json a = json::array();
      for (Eigen::Index i = 0; i < value.size(); ++i) a.push_back(value[i]);
      return a;
    } else {
      return json(value);
    }
  }

  std::vector<json*> stack_;
};

}  // namespace caps::app::detail

namespace caps::app {

template <class Request>
Request read_request(const std::string& json_text, const std::string& source) {
  const detail::json j = parse_json<detail::json>(json_text, source);
  if (!j.is_object()) throw InvalidInput(cat(source, ": expected a JSON object of options"));
  Request r;
  detail::JsonReader reader(j, source);
  Request::fields(r, reader);
  reader.finish();
  return r;
}

template <class Request>
std::string write_request(const Request& request) {
  detail::JsonWriter w;
  Request::fields(request, w);
  return detail::dump(w.j);
}

template <class Result>
Result result_from_json(const std::string& json_text, const std::string& source) {
  const detail::json j = parse_json<detail::json>(json_text, source);
  Result r;
  detail::JsonReader reader(j, source);
  Result::fields(r, reader);
  reader.finish();
  return r;
}

template <class Result>
std::string result_to_json(const Result& result) {
  detail::JsonWriter w;
  Result::fields(result, w);
  return detail::dump(w.j);
}

}  // namespace caps::app

/// Instantiates read_request and write_request for one request type (in its verb's .cpp).
#define CAPS_APP_REQUEST_JSON(Request)                                                         \
  template Request caps::app::read_request<Request>(const std::string&, const std::string&); \
  template std::string caps::app::write_request<Request>(const Request&);

/// Defines to_json() of one result type from its declared fields, and instantiates
/// result_from_json (in its verb's .cpp).
#define CAPS_APP_RESULT_JSON(Result)                                                   \
  template Result caps::app::result_from_json<Result>(const std::string&,            \
                                                      const std::string&);           \
  template std::string caps::app::result_to_json<Result>(const Result&);             \
  std::string caps::app::to_json(const Result& result) { return result_to_json(result); }
