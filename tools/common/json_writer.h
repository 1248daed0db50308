// A minimal streaming JSON writer for the tools' --json output (objects, arrays, scalars).
// Numbers are written in their shortest exact form; NaN/Inf become null (JSON has no such literals).
#pragma once

#include <cstdint>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

namespace cli {

class JsonWriter {
 public:
  explicit JsonWriter(std::ostream& out, bool pretty = true) : out_(out), pretty_(pretty) {}

  JsonWriter& begin_object();
  JsonWriter& end_object();
  JsonWriter& begin_array();
  JsonWriter& end_array();
  // Inside an object, a key must precede every value.
  JsonWriter& key(std::string_view k);
  JsonWriter& value(double v);
  JsonWriter& value(int64_t v);
  JsonWriter& value(int v) { return value(int64_t(v)); }
  JsonWriter& value(bool v);
  JsonWriter& value(std::string_view v);
  JsonWriter& value(const char* v) { return value(std::string_view(v)); }
  JsonWriter& null();
  template <typename T> JsonWriter& field(std::string_view k, const T& v) {
    key(k);
    return value(v);
  }
  // Ends the document with a newline.
  void finish();

 private:
  std::ostream& out_;
  bool pretty_;
  std::vector<bool> first_;  // per open container: no element written yet
  bool after_key_ = false;
  void before_value();
  void newline_indent();
  static void write_string(std::ostream& out, std::string_view s);
};

}  // namespace cli
