// Names for EGL error codes, so that a failed context creation says what EGL reported.
#pragma once

#include <string>

namespace isostream::render::egl {

// "EGL_BAD_MATCH" etc. for the codes of EGL 1.5; "EGL error 0x...." otherwise.
std::string EglErrorName(int code);

}  // namespace isostream::render::egl
