"""LLMConfig: which server and model F and G talk to, and how patiently; the API key never leaves it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, SecretStr

from adaptenv.adapt.llm.usage import Budget, Prices
from adaptenv.configfile import parse_config, read_json
from adaptenv.errors import ConfigError

Provider = Literal["openai", "openai-compatible"]
Api = Literal["responses", "chat"]
PromptSet = Literal["adaptenv", "paper"]

#: Base URL of the real OpenAI API (used when ``provider="openai"`` and no base_url is set).
OPENAI_BASE_URL = "https://api.openai.com/v1"
#: Key sent to OpenAI-compatible servers that do not check one (vLLM/Ollama/llama.cpp by default).
PLACEHOLDER_KEY = "not-needed"
COMPATIBLE_KEY_ENV = "ADAPTENV_LLM_API_KEY"
#: The SDK's environment variable for the server URL (read for provider 'openai' when base_url is unset).
BASE_URL_ENV = "OPENAI_BASE_URL"
#: Config keys that hold secrets; a config file or run config holding one is refused.
SECRET_FIELDS = ("api_key",)
#: The fix an LLM config's type errors suggest.
LLM_FIX = "fix that value (docs/llm.md lists the fields)"


class LLMConfig(BaseModel):
    """Connection and sampling settings of one LLM backend (saved with a run; the key is never saved)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    provider: Provider = Field("openai", description="'openai' (Responses API) or 'openai-compatible' "
                               "(Chat Completions at base_url: vLLM, Ollama, llama.cpp).")
    model: str = Field("gpt-4.1-mini", min_length=1, description="Model name as the server knows it "
                       "(the paper used gpt-4.1-mini).")
    base_url: str | None = Field(None, description="Server URL ending in /v1; required for "
                                 "'openai-compatible'; for 'openai' it defaults to $OPENAI_BASE_URL, else "
                                 "the OpenAI API.")
    api: Api | None = Field(None, description="Wire API: 'responses' (what the paper used) or 'chat' "
                            "(Chat Completions); default responses for 'openai', chat for 'openai-compatible'.")
    api_key_env: str | None = Field(None, min_length=1, description="Environment variable holding the "
                                    "API key; default OPENAI_API_KEY for 'openai' and ADAPTENV_LLM_API_KEY "
                                    "for 'openai-compatible', so an OpenAI key is never sent to another server.")
    api_key: SecretStr | None = Field(None, exclude=True, repr=False, description="API key given "
                                      "directly (prefer api_key_env); never written anywhere.")
    timeout_s: float = Field(60.0, gt=0, description="Timeout of one HTTP request, in seconds.")
    max_retries: int = Field(3, ge=0, le=10, description="Retries after a 429, 5xx, timeout or "
                             "connection error (exponential backoff with jitter).")
    backoff_base_s: float = Field(1.0, ge=0, description="First backoff delay in seconds; doubles per retry.")
    backoff_max_s: float = Field(30.0, ge=0, description="Upper bound of one backoff delay, in seconds.")
    temperature: float | None = Field(0.0, ge=0, le=2, description="Sampling temperature; None leaves "
                                      "the server default (needed by reasoning models).")
    max_output_tokens: int | None = Field(None, gt=0, description="Cap on generated tokens; None for "
                                          "the server default.")
    image_detail: Literal["auto", "low", "high"] = Field("auto", description="Vision detail level of "
                                                         "the Responses API image parts.")
    structured_output: Literal["auto", "json_schema", "json_object"] = Field(
        "auto", description="Chat Completions structured output: json_schema (parse), json_object "
        "(JSON mode + local validation) or auto (json_schema, falling back once the server rejects it).")
    cache_dir: Path | None = Field(None, description="Directory of the response cache (JSON files); "
                                   "None disables caching.")
    seed: int = Field(0, description="Seed of the backoff jitter generator.")
    prompts: PromptSet = Field("adaptenv", description="Prompt set of F and G: 'adaptenv' (richer prompts) or "
                               "'paper' (the paper's appendix prompts verbatim).")
    allow_target_moves: bool = Field(False, description="Let G move the episode's target objects (excluded "
                                     "from the move tool's enum by default, like the built-in G).")
    price_in: float | None = Field(None, ge=0, description="USD per million input tokens, for cost estimates.")
    price_out: float | None = Field(None, ge=0, description="USD per million output tokens, for cost estimates.")
    price_cached_in: float | None = Field(None, ge=0, description="USD per million cached input tokens "
                                          "(default: price_in).")
    max_tokens: int | None = Field(None, gt=0, description="Token budget (input + output) of a run; requests "
                                   "stop once it is used up.")
    max_cost: float | None = Field(None, gt=0, description="Cost budget of a run in USD (needs price_in and "
                                   "price_out); requests stop once it is used up.")

    def resolved_api(self) -> Api:
        """The wire API requests use."""
        if self.api is not None:
            return self.api
        return "responses" if self.provider == "openai" else "chat"

    def prices(self) -> Prices | None:
        """Token prices, or None when price_in/price_out are not both set."""
        if self.price_in is None or self.price_out is None:
            return None
        return Prices(self.price_in, self.price_out, self.price_cached_in)

    def budget(self) -> Budget:
        """The token/cost budget (raises ConfigError when max_cost has no prices)."""
        return Budget(self.max_tokens, self.max_cost, self.prices())

    def describe(self) -> dict[str, object]:
        """What a run records about the model it used: never the key."""
        return {"provider": self.provider, "api": self.resolved_api(), "model": self.model,
                "base_url": self.resolved_base_url(), "prompts": self.prompts, "temperature": self.temperature,
                "allow_target_moves": self.allow_target_moves, "api_key_env": self.key_env(),
                "price_in": self.price_in, "price_out": self.price_out, "price_cached_in": self.price_cached_in,
                "max_tokens": self.max_tokens, "max_cost": self.max_cost}

    def key_env(self) -> str:
        """The environment variable the API key is read from."""
        if self.api_key_env:
            return self.api_key_env
        return "OPENAI_API_KEY" if self.provider == "openai" else COMPATIBLE_KEY_ENV

    def resolved_base_url(self) -> str:
        """The base URL requests go to; raises ConfigError when a compatible server has none."""
        if self.base_url:
            return self.base_url.rstrip("/")
        if self.provider == "openai" and os.environ.get(BASE_URL_ENV):
            return os.environ[BASE_URL_ENV].rstrip("/")
        if self.provider == "openai-compatible":
            raise ConfigError("the LLM config field base_url is empty but provider 'openai-compatible' "
                              "needs it: set base_url, e.g. http://localhost:11434/v1 for Ollama")
        return OPENAI_BASE_URL


def resolve_api_key(config: LLMConfig) -> str:
    """The API key from the config value or the environment; a placeholder for compatible servers.

    Raises ConfigError (without any key material) when the real OpenAI provider has no key.
    """
    if config.api_key is not None and config.api_key.get_secret_value():
        return config.api_key.get_secret_value()
    from_env = os.environ.get(config.key_env(), "")
    if from_env:
        return from_env
    if config.provider == "openai-compatible":
        return PLACEHOLDER_KEY
    raise ConfigError(f"the LLM provider 'openai' needs an API key but the environment variable "
                      f"{config.key_env()} is not set: export it (field api_key_env names the "
                      f"variable), or use provider 'openai-compatible' with base_url for a local server")


def refuse_secrets(data: object, where: str) -> None:
    """Raise ConfigError when a config section holds an API key (keys come from the environment only)."""
    if isinstance(data, dict):
        found = [k for k in SECRET_FIELDS if data.get(k)]
        if found:
            raise ConfigError(f"{where}: field {found[0]} holds an API key, which would be saved with the run; "
                              f"remove it, export the key (OPENAI_API_KEY) and name the variable in api_key_env")


def load_llm_config(path: str | Path) -> LLMConfig:
    """Read an LLMConfig from a JSON file (exact JSON types, unknown fields refused); errors name the file and field."""
    path = Path(path)
    data = read_json(path, "LLM config (docs/llm.md)")
    refuse_secrets(data, f"{path}")
    return parse_config(LLMConfig, data, f"{path} (LLM config)", fix=LLM_FIX)
