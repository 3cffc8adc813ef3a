// One exception type for the whole project: "component: message naming the value".
#pragma once

#include <stdexcept>
#include <string>

namespace lpm {

class Error : public std::runtime_error {
public:
    Error(const std::string& component, const std::string& message) : std::runtime_error(component + ": " + message) {}
};

/// A setting out of its range, thrown by a settings struct's validate(): `field` names the
/// struct member ("directionsPerFace"), `rule` says what is wrong ("must be in 1..64, got
/// 65"). A front end maps the field to its own name for it (the CLI: a flag).
class SettingError : public Error {
public:
    SettingError(const std::string& component, const std::string& field, const std::string& rule)
        : Error(component, field + " " + rule), field_(field), rule_(rule) {}
    const std::string& field() const { return field_; }
    const std::string& rule() const { return rule_; }

private:
    std::string field_, rule_;
};

}  // namespace lpm
