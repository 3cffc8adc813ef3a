// One exception type for the whole project: "component: message naming the value".
#pragma once

#include <stdexcept>
#include <string>

namespace lpm {

class Error : public std::runtime_error {
public:
    Error(const std::string& component, const std::string& message)
        : std::runtime_error(component + ": " + message) {}
};

}  // namespace lpm
