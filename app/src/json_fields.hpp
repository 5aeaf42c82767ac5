#pragma once
// The JSON side of the request fields (app/include/caps/app/fields.hpp), for app/src only.

#include <nlohmann/json.hpp>
#include <map>
#include <optional>
#include <set>
#include <string>

#include "caps/app/fields.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"

namespace caps::app::detail {

using nlohmann::json;

/// Fills a request's fields from a JSON object.
class JsonReader {
 public:
  JsonReader(const json& j, std::string source) : j_(j), source_(std::move(source)) {}

  template <class T>
  void operator()(T& value, const Field& f) {
    const std::string key(f.key);
    seen_.insert(key);
    if (!j_.contains(key)) {
      if (f.kind == FieldKind::Required || f.kind == FieldKind::Positional)
        throw InvalidInput(cat(source_, ": \"", key, "\" is required (", f.help, ")"));
      return;
    }
    const json& v = j_.at(key);
    if (v.is_null()) return;
    read(v, value, key);
  }

  /// Refuses keys that are no field.
  void check_unknown() const {
    for (const auto& [k, v] : j_.items())
      if (!seen_.count(k)) throw InvalidInput(cat(source_, ": unknown key \"", k, "\""));
  }

 private:
  [[noreturn]] void wrong(const std::string& key, const char* expected, const json& v) const {
    throw InvalidInput(cat(source_, ": \"", key, "\" must be ", expected, ", not ", v.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
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

  const json& j_;
  std::string source_;
  std::set<std::string> seen_;
};

/// Writes a request's fields into a JSON object.
class JsonWriter {
 public:
  template <class T>
  void operator()(const T& value, const Field& f) {
    if constexpr (std::is_same_v<T, std::optional<double>>) {
      j[std::string(f.key)] = value ? json(*value) : json(nullptr);
    } else {
      j[std::string(f.key)] = value;
    }
  }
  json j = json::object();
};

}  // namespace caps::app::detail

namespace caps::app {

template <class Request>
Request read_request(const std::string& json_text, const std::string& source) {
  check_json_depth(json_text, source);
  detail::json j;
  try {
    j = detail::json::parse(json_text, nullptr, true, false);
  } catch (const detail::json::exception& e) {
    throw InvalidInput(cat(source, ": not valid JSON (", e.what(), ")"));
  }
  if (!j.is_object()) throw InvalidInput(cat(source, ": expected a JSON object of options"));
  Request r;
  detail::JsonReader reader(j, source);
  Request::fields(r, reader);
  reader.check_unknown();
  return r;
}

template <class Request>
std::string write_request(const Request& request) {
  detail::JsonWriter w;
  Request::fields(request, w);
  return w.j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace caps::app

/// Instantiates read_request and write_request for one request type (in its verb's .cpp).
#define CAPS_APP_REQUEST_JSON(Request)                                                         \
  template Request caps::app::read_request<Request>(const std::string&, const std::string&); \
  template std::string caps::app::write_request<Request>(const Request&);
