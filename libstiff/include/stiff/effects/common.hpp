/// \file effects/common.hpp
/// What an effect source file includes. Generic code rules (style.md 3.3): literals as T(x),
/// never cast T to double, maths functions unqualified after `using std::sin;`.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "stiff/effect.hpp"
#include "stiff/error.hpp"
