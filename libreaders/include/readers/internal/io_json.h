// A tiny parser for the flat JSON objects used as raw-grid sidecars ({"width": 1201, "type": "int16"}).
// Robust to hostile input: bounded nesting, no recursion beyond that bound, errors instead of crashes.
#pragma once

#include <map>
#include <optional>
#include <string>

#include "core/text.h"

namespace terrain::io {

struct JsonScalar {
  enum class Kind { Null, Bool, Number, String, Composite } kind = Kind::Null;
  double number = 0;  // Kind::Number (also 1/0 for Bool)
  std::string text;   // Kind::String, or the literal text of a number
};

// Top-level members of a JSON object; nested objects/arrays are accepted but kept only as Composite.
using JsonObject = std::map<std::string, JsonScalar>;

// Parses `text` as one JSON object. On failure returns nullopt and sets `error` to a short
// description with the byte offset (e.g. "expected ':' at byte 17").
std::optional<JsonObject> parse_json_object(const std::string& text, std::string& error);

}  // namespace terrain::io
