// Flat JSON object parser for sidecars: a hand-written recursive-descent parser over a string.
#include "readers/internal/io_json.h"

#include <charconv>
#include <cstdio>

namespace terrain::io {
namespace {

constexpr int kMaxDepth = 32;  // nested values are skipped, but hostile nesting must not blow the stack

class Parser {
 public:
  explicit Parser(const std::string& text) : s_(text) {}

  std::optional<JsonObject> parse_top(std::string& error) {
    JsonObject out;
    skip_ws();
    if (!expect('{')) return report(error);
    skip_ws();
    if (peek() == '}') {
      ++pos_;
    } else {
      for (;;) {
        skip_ws();
        std::string key;
        if (!parse_string(key)) return report(error);
        skip_ws();
        if (!expect(':')) return report(error);
        skip_ws();
        JsonScalar value;
        if (!parse_value(value, 1)) return report(error);
        if (out.count(key)) {
          err_ = "duplicate key \"" + key + "\"";
          return report(error);
        }
        out.emplace(std::move(key), std::move(value));
        skip_ws();
        if (peek() == ',') {
          ++pos_;
          continue;
        }
        if (!expect('}')) return report(error);
        break;
      }
    }
    skip_ws();
    if (pos_ != s_.size()) {
      err_ = "trailing characters";
      return report(error);
    }
    return out;
  }

 private:
  const std::string& s_;
  size_t pos_ = 0;
  std::string err_;

  std::optional<JsonObject> report(std::string& error) {
    error = (err_.empty() ? std::string("malformed JSON") : err_) + " at byte " + std::to_string(pos_);
    return std::nullopt;
  }
  char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
  void skip_ws() {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r'))
      ++pos_;
  }
  bool expect(char c) {
    if (peek() == c && pos_ < s_.size()) {
      ++pos_;
      return true;
    }
    err_ = std::string("expected '") + c + "'";
    return false;
  }
  bool literal(const char* word) {
    size_t n = std::char_traits<char>::length(word);
    if (s_.compare(pos_, n, word) == 0) {
      pos_ += n;
      return true;
    }
    err_ = "unknown literal";
    return false;
  }

  static void append_utf8(std::string& out, unsigned cp) {
    if (cp < 0x80) {
      out += char(cp);
    } else if (cp < 0x800) {
      out += char(0xC0 | (cp >> 6));
      out += char(0x80 | (cp & 0x3F));
    } else if (cp < 0x10000) {
      out += char(0xE0 | (cp >> 12));
      out += char(0x80 | ((cp >> 6) & 0x3F));
      out += char(0x80 | (cp & 0x3F));
    } else {
      out += char(0xF0 | (cp >> 18));
      out += char(0x80 | ((cp >> 12) & 0x3F));
      out += char(0x80 | ((cp >> 6) & 0x3F));
      out += char(0x80 | (cp & 0x3F));
    }
  }

  bool parse_hex4(unsigned& cp) {
    if (pos_ + 4 > s_.size()) {
      err_ = "short \\u escape";
      return false;
    }
    cp = 0;
    for (int i = 0; i < 4; ++i) {
      char c = s_[pos_++];
      cp <<= 4;
      if (c >= '0' && c <= '9')
        cp |= unsigned(c - '0');
      else if (c >= 'a' && c <= 'f')
        cp |= unsigned(c - 'a' + 10);
      else if (c >= 'A' && c <= 'F')
        cp |= unsigned(c - 'A' + 10);
      else {
        err_ = "bad \\u escape";
        return false;
      }
    }
    return true;
  }

  bool parse_string(std::string& out) {
    if (!expect('"')) return false;
    for (;;) {
      if (pos_ >= s_.size()) {
        err_ = "unterminated string";
        return false;
      }
      char c = s_[pos_++];
      if (c == '"') return true;
      if (static_cast<unsigned char>(c) < 0x20) {
        err_ = "control character in string";
        return false;
      }
      if (c != '\\') {
        out += c;
        continue;
      }
      if (pos_ >= s_.size()) {
        err_ = "unterminated escape";
        return false;
      }
      char e = s_[pos_++];
      switch (e) {
        case '"':
          out += '"';
          break;
        case '\\':
          out += '\\';
          break;
        case '/':
          out += '/';
          break;
        case 'b':
          out += '\b';
          break;
        case 'f':
          out += '\f';
          break;
        case 'n':
          out += '\n';
          break;
        case 'r':
          out += '\r';
          break;
        case 't':
          out += '\t';
          break;
        case 'u': {
          unsigned cp = 0;
          if (!parse_hex4(cp)) return false;
          // A lone or malformed surrogate is kept as U+FFFD rather than rejected: keys are ASCII anyway.
          if (cp >= 0xD800 && cp <= 0xDBFF && s_.compare(pos_, 2, "\\u") == 0) {
            pos_ += 2;
            unsigned lo = 0;
            if (!parse_hex4(lo)) return false;
            cp = (lo >= 0xDC00 && lo <= 0xDFFF) ? 0x10000 + ((cp - 0xD800) << 10) + (lo - 0xDC00) : 0xFFFD;
          } else if (cp >= 0xD800 && cp <= 0xDFFF) {
            cp = 0xFFFD;
          }
          append_utf8(out, cp);
          break;
        }
        default:
          err_ = "bad escape";
          return false;
      }
    }
  }

  bool parse_number(JsonScalar& out) {
    size_t start = pos_;
    // JSON number grammar: -?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?
    if (peek() == '-') ++pos_;
    auto digits = [&] {
      size_t d = pos_;
      while (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
      return pos_ - d;
    };
    if (peek() == '0')
      ++pos_;
    else if (digits() == 0) {
      err_ = "bad number";
      return false;
    }
    if (peek() == '.') {
      ++pos_;
      if (digits() == 0) {
        err_ = "bad number";
        return false;
      }
    }
    if (peek() == 'e' || peek() == 'E') {
      ++pos_;
      if (peek() == '+' || peek() == '-') ++pos_;
      if (digits() == 0) {
        err_ = "bad number";
        return false;
      }
    }
    out.kind = JsonScalar::Kind::Number;
    out.text = s_.substr(start, pos_ - start);
    auto res = std::from_chars(s_.data() + start, s_.data() + pos_, out.number);
    if (res.ec != std::errc()) {
      err_ = "number out of range";
      pos_ = start;
      return false;
    }
    return true;
  }

  bool parse_value(JsonScalar& out, int depth) {
    if (depth > kMaxDepth) {
      err_ = "nesting too deep";
      return false;
    }
    char c = peek();
    if (c == '"') {
      out.kind = JsonScalar::Kind::String;
      return parse_string(out.text);
    }
    if (c == '-' || (c >= '0' && c <= '9')) return parse_number(out);
    if (c == 't') {
      out.kind = JsonScalar::Kind::Bool;
      out.number = 1;
      return literal("true");
    }
    if (c == 'f') {
      out.kind = JsonScalar::Kind::Bool;
      out.number = 0;
      return literal("false");
    }
    if (c == 'n') {
      out.kind = JsonScalar::Kind::Null;
      return literal("null");
    }
    if (c == '{' || c == '[') {
      char close = c == '{' ? '}' : ']';
      ++pos_;
      out.kind = JsonScalar::Kind::Composite;
      skip_ws();
      if (peek() == close) {
        ++pos_;
        return true;
      }
      for (;;) {
        skip_ws();
        if (c == '{') {
          std::string key;
          if (!parse_string(key)) return false;
          skip_ws();
          if (!expect(':')) return false;
          skip_ws();
        }
        JsonScalar inner;
        if (!parse_value(inner, depth + 1)) return false;
        skip_ws();
        if (peek() == ',') {
          ++pos_;
          continue;
        }
        return expect(close);
      }
    }
    err_ = pos_ >= s_.size() ? "unexpected end" : "unexpected character";
    return false;
  }
};

}  // namespace

std::optional<JsonObject> parse_json_object(const std::string& text, std::string& error) {
  Parser p(text);
  return p.parse_top(error);
}

}  // namespace terrain::io
