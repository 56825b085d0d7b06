#include "video3dgs/core/error.hpp"

#include <string>

#include <doctest/doctest.h>

using namespace video3dgs;

TEST_CASE("error: message starts with the stable id, then the place at fault") {
  const io_error e("io.unreadable", "frames/00012.jpg", "cannot decode image");
  CHECK(std::string(e.what()) == "[io.unreadable] frames/00012.jpg: cannot decode image");
  CHECK(e.id() == "io.unreadable");
  CHECK(e.where() == "frames/00012.jpg");
  const error& base = e;
  CHECK(base.id() == "io.unreadable");
  const option_error o("option.range", "", "k must be >= 2");
  CHECK(std::string(o.what()) == "[option.range] k must be >= 2");
}

TEST_CASE("error: is() matches the id and the old spellings of version 0.1, nothing else") {
  const numeric_error n("numeric.non_finite", "x", "NaN");
  CHECK(n.is("numeric.non_finite"));
  CHECK(n.is("numeric.nonfinite"));
  CHECK(!n.is("numeric.non"));
  const io_error f("io.format", "a.ply", "bad header");
  CHECK(f.is("io.format"));
  CHECK(f.is("io.malformed"));
  CHECK(!f.is("io.truncated"));
  CHECK(!io_error("io.truncated", "", "").is("io.malformed"));
}
