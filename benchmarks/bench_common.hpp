// What every benchmark program shares: medians, wall and process-CPU timing of a pass, the load
// average and comma lists on the command line. Wall time is what a user waits; the process CPU time
// (all threads) is the work done, which on a shared machine stays readable when the wall time is not.
#pragma once

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <limits>
#include <sstream>
#include <string>
#include <system_error>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "video3dgs/core/error.hpp"

namespace video3dgs::bench {

/// Median (the mean of the middle two for an even count); 0 for no samples.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// CPU time of the whole process (all threads), ms.
inline double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * double(ts.tv_sec) + 1e-6 * double(ts.tv_nsec);
}

/// 1-minute load average (other processes competing for the cores); -1 where unknown.
inline double load_avg() {
  double l[1];
  return getloadavg(l, 1) == 1 ? l[0] : -1.0;
}

/// The whole of `text` read as a T (an integer or a floating-point type), for a command-line value.
/// An integer may be written as a real with an integral value ("1e9", "3000.0") up to 2^53.
/// @throws option_error `option.number` naming `flag` when the text is empty, has anything after the
/// number, is out of T's range, is not integral for an integer T, or is not finite: atoi/strtol would
/// have read 0 or a prefix (strtol read "1e9" as 1). A number that is not a whole number in an integer
/// T's range is told so, with the range.
template <class T>
T parse_number(const std::string& flag, const std::string& text) {
  const char* first = text.data();
  const char* const last = first + text.size();
  if (first != last && *first == '+') ++first;  // from_chars takes no leading '+'
  const auto bad = [&] { return option_error("option.number", flag, "expected a number, got \"" + text + "\""); };
  T value{};
  const auto read = std::from_chars(first, last, value);
  if constexpr (std::is_integral_v<T>) {
    if (read.ec == std::errc{} && read.ptr == last) return value;
    double real = 0;
    const auto [end, ec] = std::from_chars(first, last, real);
    constexpr double exact = 9007199254740992.0;  // 2^53: every integer up to it is a double
    if (ec != std::errc{} || end != last) throw bad();
    if (real != std::floor(real) || std::fabs(real) > exact || real < double(std::numeric_limits<T>::min()) ||
        real > double(std::numeric_limits<T>::max()))
      throw option_error("option.number", flag,
                         "expected a whole number from " + std::to_string(std::numeric_limits<T>::min()) + " to " +
                             std::to_string(std::numeric_limits<T>::max()) + ", got \"" + text + "\"");
    return T(real);
  } else {
    if (read.ec != std::errc{} || read.ptr != last || !std::isfinite(value)) throw bad();
    return value;
  }
}

/// "a,b,,c" -> {"a", "b", "c"}.
inline std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

/// Wall and process-CPU milliseconds of repeated runs of one pass.
struct Samples {
  std::vector<double> wall, cpu;
  double wall_ms() const { return median(wall); }
  double cpu_ms() const { return median(cpu); }
};

/// Runs f once and appends its wall and CPU time to s.
template <class F>
void measure(Samples& s, F&& f) {
  const double c0 = process_cpu_ms();
  const auto t0 = std::chrono::steady_clock::now();
  f();
  const auto t1 = std::chrono::steady_clock::now();
  s.cpu.push_back(process_cpu_ms() - c0);
  s.wall.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
}

/// `v` rounded to `digits` decimals (JSON lines stay short; timings are not more precise than that).
inline double round_to(double v, int digits) {
  const double s = std::pow(10.0, digits);
  return std::isfinite(v) ? std::round(v * s) / s : v;
}

/// Prints one JSON line (nlohmann/json: numbers that are not finite become null) and flushes.
inline void emit(const nlohmann::ordered_json& line) {
  std::printf("%s\n", line.dump().c_str());
  std::fflush(stdout);
}

}  // namespace video3dgs::bench
