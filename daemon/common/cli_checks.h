#pragma once
/// @file
/// Checks of command-line values shared by hullguardd and hullguard (CLI11).

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <type_traits>

#include <CLI/CLI.hpp>

namespace hg::cli {

/// The value must be a finite number: CLI11's ranges let NaN through, and an
/// infinite duration or position means nothing here.
inline const CLI::Validator kFinite(
    [](std::string& text) -> std::string {
      try {
        std::size_t used = 0;
        const double value = std::stod(text, &used);
        if (used == text.size() && std::isfinite(value)) return "";
      } catch (const std::exception&) {
        // Not a number at all: the option's own conversion reports it.
        return "";
      }
      return "'" + text + "' is not a finite number";
    },
    "FINITE");

namespace detail {

/// Parses all of `text` as a T (integers: decimal, an optional sign); false
/// when it is not one.
template <typename T>
bool ParseWhole(const std::string& text, T* value) {
  if constexpr (std::is_integral_v<T>) {
    const char* begin = text.data();
    const char* end = text.data() + text.size();
    if (begin != end && *begin == '+') ++begin;
    const auto [stop, error] = std::from_chars(begin, end, *value);
    return error == std::errc() && stop == end && begin != end;
  } else {
    char* stop = nullptr;
    const double parsed = std::strtod(text.c_str(), &stop);
    *value = static_cast<T>(parsed);
    return !text.empty() && stop == text.c_str() + text.size();
  }
}

template <typename T>
std::string Show(T value) {
  if constexpr (std::is_integral_v<T>) {
    return std::to_string(value);
  } else {
    char buffer[32];
    std::snprintf(buffer, sizeof(buffer), "%g", static_cast<double>(value));
    return buffer;
  }
}

}  // namespace detail

/// The value must be a T (an integer for integral T) within [lo, hi]. Unlike
/// CLI::Range, says which of the two it is not ("'abc' is not an integer",
/// "'17' is not in 3..16").
template <typename T>
CLI::Validator Range(T lo, T hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        T value{};
        if (!detail::ParseWhole(text, &value)) {
          return "'" + text + "' is not " +
                 (std::is_integral_v<T> ? std::string("an integer") : std::string("a number"));
        }
        if (!(value >= lo && value <= hi)) {
          return "'" + text + "' is not in " + detail::Show(lo) + ".." + detail::Show(hi);
        }
        return "";
      },
      "[" + detail::Show(lo) + ".." + detail::Show(hi) + "]");
}

/// The value must be a finite number >= 0 (kNonNegative) or > 0 (kPositive).
inline const CLI::Validator kNonNegative(
    [](std::string& text) -> std::string {
      double value = 0.0;
      if (!detail::ParseWhole(text, &value)) return "'" + text + "' is not a number";
      if (!std::isfinite(value)) return "'" + text + "' is not a finite number";
      return value >= 0.0 ? "" : "'" + text + "' must be 0 or more";
    },
    ">= 0");
inline const CLI::Validator kPositive(
    [](std::string& text) -> std::string {
      double value = 0.0;
      if (!detail::ParseWhole(text, &value)) return "'" + text + "' is not a number";
      if (!std::isfinite(value)) return "'" + text + "' is not a finite number";
      return value > 0.0 ? "" : "'" + text + "' must be more than 0";
    },
    "> 0");

}  // namespace hg::cli
