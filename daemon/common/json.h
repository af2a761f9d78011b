#pragma once
/// @file
/// JSON string literals for the commands' `--json` output.

#include <cstdio>
#include <string>
#include <string_view>

namespace hg::common {

/// `text` as a JSON string literal, quotes included: `"` and `\` escaped,
/// control characters as \u00XX, everything else (UTF-8 too) as it is. Names
/// from configs and scenes may hold anything; the output stays valid JSON.
inline std::string JsonString(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", c);
      out += buf;
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

}  // namespace hg::common
