// Text forms shared by every tool and library that writes JSON or numbers for people and programs.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace terrain {

// s as a JSON string literal, quotes included: '"' and '\' escaped, \n \r \t by name, other control
// characters as \u00XX; every other byte (UTF-8 included) unchanged. Pure, thread-safe.
std::string json_quote(std::string_view s);

// The shortest decimal text that reads back as exactly v, locale-independent ("0.1", "1e+20",
// "-0"); "nan", "inf" and "-inf" for the non-finite values (callers writing JSON map those to null).
std::string shortest(double v);

// A coordinate reference system's text (WKT or PROJ) as readers take it from a file and the .pyr
// stores it: at most kMaxCrsTextBytes bytes, none a control character other than tab, LF and CR
// (UTF-8 and other bytes >= 0x80 pass). Pure.
inline constexpr size_t kMaxCrsTextBytes = 8192;
bool is_crs_text(std::string_view s);

// names[e] for an enum whose values are 0, 1, ... in the order of `names`; "unknown" for any other
// value (a value read from a file may be anything). The one way enum names are written.
template <class Enum, size_t N> const char* enum_name(Enum e, const char* const (&names)[N]) {
  const auto i = static_cast<unsigned long long>(e);
  return i < N ? names[i] : "unknown";
}

}  // namespace terrain
