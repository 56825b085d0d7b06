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
